"""`wavestack analyze` and `fit` on measured maps: the file's own pixels, the `auto` fit method on a
long thin strip, advice that works, 4D .h5 files and unsupported files."""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.cli import main
from wavestack.pipeline import read_metropro_dat

from shared_data import DATA, require_shared_data

_NO_DATA = 1e300  # the .datx "No Data" marker our synthetic files use


def _write_datx(path: Path, surface_nm: np.ndarray) -> None:
    """A .datx in the layout our reader reads: Measurement/Surface in nm, NaN -> No Data."""
    with h5py.File(path, "w") as h5:
        node = h5.create_dataset("Measurement/Surface", data=np.where(np.isnan(surface_nm), _NO_DATA, surface_nm))
        node.attrs["Unit"] = "NanoMeters"
        node.attrs["No Data"] = _NO_DATA
        node.attrs["Wavelength"] = 632.8e-9


def _strip_map(seed: int = 3) -> np.ndarray:
    """A 259 x 33 strip (rows x cols = 33 x 259): tilt, bend and twist plus 2 nm of noise, nm."""
    rows, cols = np.mgrid[:33, :259].astype(np.float64)
    inside = ((rows - 16) / 16.5) ** 2 + ((cols - 129) / 129.5) ** 2 <= 1
    x, y = (cols - 129) / 129.5, (rows - 16) / 16.5
    surface = 40 * x - 15 * y + 60 * x**2 + 8 * x * y + np.random.default_rng(seed).normal(0, 2, x.shape)
    return np.where(inside, surface, np.nan)


def _run(capsys, *argv: str) -> dict:
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _one_line_error(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1 and "Traceback" not in captured.err, captured.err
    return lines[0]


def test_strip_default_is_the_mapped_basis_with_its_reason(capsys, tmp_path) -> None:
    strip = tmp_path / "strip.datx"
    surface = _strip_map()
    _write_datx(strip, surface)
    report = _run(capsys, "analyze", str(strip))
    assert report["fit_method"] == "csf-qcm"
    assert "circle basis is degenerate" in report["fit_method_reason"]
    assert report["pixels"]["measured"] == report["pixels"]["fitted"] == int(np.isfinite(surface).sum())
    assert report["diagnostics"]["noise_gain"] < 100  # the chosen basis is well conditioned
    text_lines = [line for line in (main(["analyze", str(strip)]), capsys.readouterr().out)[1].splitlines()
                  if line.startswith("fit method")]
    assert len(text_lines) == 1 and "csf-qcm" in text_lines[0]


def test_strip_circle_fails_truthfully_and_its_advice_works(capsys, tmp_path) -> None:
    strip = tmp_path / "strip.datx"
    _write_datx(strip, _strip_map())
    message = _one_line_error(capsys, ["analyze", str(strip), "--fit-method", "circle"])
    shown = re.search(r"kappa\(G\) = ([0-9.e+]+) .* above the limit ([0-9.e+]+)", message)
    assert shown and float(shown.group(1)) > float(shown.group(2)) == 2.0**52, message
    advice = re.search(r"\(on this command line: (.*)\)$", message)
    assert advice and "--fit-method csf-qcm" in advice.group(1), message
    for option in advice.group(1).split(" or "):
        report = _run(capsys, "analyze", str(strip), "--fit-method", "circle", *option.split())
        assert report["pixels"]["fitted"] == report["pixels"]["measured"]


def test_fit_command_on_the_strip_defaults_to_auto_and_advises_its_own_flags(capsys, tmp_path) -> None:
    strip = tmp_path / "strip.datx"
    _write_datx(strip, _strip_map())
    report = _run(capsys, "fit", str(strip))
    assert report["method"] == "csf-qcm" and report["method_reason"]
    message = _one_line_error(capsys, ["fit", str(strip), "--method", "qr"])
    assert "(on this command line: --method csf-qcm" in message


def test_drop_outs_and_isolated_pixels_are_counted_not_invented(capsys, tmp_path) -> None:
    rows, cols = np.mgrid[:101, :101]
    disk = (rows - 50) ** 2 + (cols - 50) ** 2 <= 45**2
    surface = np.where(disk, 0.05 * cols + 0.002 * (rows - 50) ** 2, np.nan)
    dropouts = [(30, 30), (50, 51), (70, 64), (41, 75), (60, 20)]
    for r, c in dropouts:
        surface[r, c] = np.nan
    surface[50, 97] = surface[3, 50] = 1.0  # isolated measured pixels outside the disk
    path, saved = tmp_path / "d.datx", tmp_path / "analysed.npy"
    _write_datx(path, surface)
    valid = np.isfinite(surface)
    report = _run(capsys, "analyze", str(path), "--modes", "15", "--save-map", str(saved), "--no-clip")
    pixels = report["pixels"]
    assert pixels["measured"] == pixels["fitted"] == int(valid.sum())
    assert pixels["dropouts_inside_aperture"] == len(dropouts)
    # the two isolated pixels at least (the outline detection also trims single-pixel rim tips)
    assert pixels["outside_detected_outline"] >= 2
    assert report["aperture"]["valid_pixels"] == int(valid.sum())
    assert np.array_equal(np.isfinite(np.load(saved)), valid)  # exactly the file's pixels
    # with spike clipping (the default) the two isolated pixels, 1 wave off the surface, are spikes:
    # left out of the fit and of the saved map, and counted (a rim pixel the 15 terms leave a few
    # residual RMS off may go with them: every clipped pixel is counted, none silently)
    clipped = _run(capsys, "analyze", str(path), "--modes", "15", "--save-map", str(saved))
    count = clipped["quality"]["clipped"]
    assert 2 <= count <= 4 and clipped["pixels"]["fitted"] == int(valid.sum()) - count
    assert np.isfinite(np.load(saved)).sum() == int(valid.sum()) - count
    assert not np.isfinite(np.load(saved)[[50, 3], [97, 50]]).any()


@require_shared_data()
def test_zygo_file_fits_exactly_its_valid_pixels(capsys, tmp_path) -> None:
    path = DATA / "zygo-dat" / "valid_zygo_dat_file.dat"
    valid = np.isfinite(read_metropro_dat(path).phase_nm)  # the file's validity, counted here
    saved = tmp_path / "analysed.npy"
    report = _run(capsys, "analyze", str(path), "--modes", "15", "--save-map", str(saved), "--no-clip")
    assert report["pixels"]["measured"] == report["pixels"]["fitted"] == int(valid.sum())
    assert report["aperture"]["valid_pixels"] == int(valid.sum())
    assert np.array_equal(np.isfinite(np.load(saved)), valid)
    assert report["fit_method"] == "circle"  # a round part: auto keeps the circle basis
    main(["analyze", str(path), "--modes", "15", "--no-clip"])
    text = capsys.readouterr().out
    assert f"pixels      {int(valid.sum())} measured, {int(valid.sum())} fitted, " in text


def test_4d_file_is_analysed_and_fitted(capsys, tmp_path) -> None:
    rows, cols = np.mgrid[:64, :64]
    disk = (rows - 31.5) ** 2 + (cols - 31.5) ** 2 < 30**2
    waves = np.where(disk, 0.1 + 0.002 * cols, np.float32(3.4028235e38)).astype(np.float32)
    path = tmp_path / "meas.h5"
    with h5py.File(path, "w") as h5:
        genraw = h5.create_group("measurement0/genraw")
        genraw.attrs["wavelength"] = "632.8 nm"
        genraw.attrs["xpix"] = "0.2 mm"
        genraw.create_dataset("data", data=waves)
    report = _run(capsys, "analyze", str(path), "--modes", "6")
    assert report["wavelength_nm"] == pytest.approx(632.8)
    assert report["pixels"]["measured"] == report["pixels"]["fitted"] == int(disk.sum())
    # tilt of 0.002 wave per pixel over the unit-RMS tilt x term: 0.002 * R / 2 waves (R the pupil
    # radius in pixels); the file's map goes nm -> waves with the file's wavelength
    radius = report["aperture"]["radius"]
    assert report["coefficients_waves"][1] == pytest.approx(0.002 * radius / 2, rel=1e-3)
    fitted = _run(capsys, "fit", str(path), "--modes", "6")
    assert fitted["valid_pixels"] == int(disk.sum())


@pytest.mark.parametrize(
    ("name", "kind"), [("scan.mat", "MATLAB files"), ("scan.xyz", "XYZ point files"), ("scan.foo", "'.foo' files")]
)
def test_unsupported_files_say_so_first(capsys, tmp_path, name: str, kind: str) -> None:
    path = tmp_path / name
    path.write_bytes(b"\x00" * 64)
    message = _one_line_error(capsys, ["analyze", str(path)])
    assert message.endswith(f"{path}: {kind} are not supported; expected .npy, .dat, .datx, 4D .h5, or images")
    assert "--wavelength-nm" not in message


def test_unknown_hdf5_layout_is_named(capsys, tmp_path) -> None:
    path = tmp_path / "camera.h5"
    with h5py.File(path, "w") as h5:
        h5.create_dataset("frames", data=np.zeros((2, 4, 4)))
    message = _one_line_error(capsys, ["analyze", str(path)])
    assert "camera.h5: an HDF5 file of unknown layout (top level: frames)" in message
    assert "--wavelength-nm" not in message


# Long thin strips from real instruments fit by default with kappa(G) <= 20: a basis orthonormal on
# the samples gives 1, a 33 x 259 elliptical strip 7.9 (tests/pipeline/fit/test_auto.py); 20 leaves
# room for ragged edges and drop-outs while a map whose domain reaches past the samples (122 on the
# real strip, thousands on the synthetic one below) is well outside it.
_STRIP_GRAM_CONDITION = 20.0


def _ragged_strip(seed: int = 4) -> np.ndarray:
    """A 259 x 37 strip, 31 px wide and 8:1, its sides slanted by 3 px (a pixel staircase on both
    edges, as on the real Zygo strip), its ends rounded, with twelve 3 x 2 px drop-outs inside."""
    rows, cols = np.mgrid[:259, :37].astype(np.float64)
    along = (rows - 129) / 129  # -1 .. 1 along the strip
    half_width = 15.5 * np.sqrt(np.clip(1 - along**8, 0, 1))
    valid = np.abs(cols - (16.5 + 3 * rows / 258)) <= half_width
    rng = np.random.default_rng(seed)
    for _ in range(12):
        row, col = rng.integers(20, 239), rng.integers(6, 28)
        valid[row:row + 3, col:col + 2] = False
    return valid


def test_ragged_strip_with_drop_outs_fits_well_conditioned_by_default(capsys, tmp_path) -> None:
    valid = _ragged_strip()
    rows, cols = np.mgrid[:259, :37].astype(np.float64)
    surface = np.where(valid, 30 * (rows / 258) ** 2 - 4 * cols / 36, np.nan)
    path = tmp_path / "ragged.datx"
    _write_datx(path, surface)
    report = _run(capsys, "analyze", str(path))
    assert report["fit_method"] == "csf-qcm"
    # every measured pixel is fitted but those spike clipping left out (counted), and no drop-out
    assert report["pixels"]["measured"] == int(valid.sum())
    assert report["pixels"]["fitted"] == int(valid.sum()) - report["quality"]["clipped"]
    assert report["pixels"]["dropouts_inside_aperture"] >= 12 * 6  # every drop-out counted, none fitted
    assert report["diagnostics"]["gram_condition"] <= _STRIP_GRAM_CONDITION
    # the surface is a smooth quadratic: the fit explains it to well under a nm
    assert report["residual_rms_waves"] * report["wavelength_nm"] < 0.5


@require_shared_data()
def test_real_zygo_strip_fits_well_conditioned_by_default(capsys) -> None:
    path = DATA / "external" / "monolithic_zygo_test.datx"
    report = _run(capsys, "analyze", str(path))
    assert report["fit_method"] == "csf-qcm"
    assert report["pixels"]["measured"] == report["pixels"]["fitted"] == 7771
    assert report["diagnostics"]["gram_condition"] <= _STRIP_GRAM_CONDITION
