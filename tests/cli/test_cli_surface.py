"""The surface figures on the command line: `analyze` and `fit` with --spec, --psd, --slope-length-mm,
--filter; their JSON, their text, their plot panels, and bad input in one line."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from shared_data import DATA, require_shared_data
from wavestack.cli import main
from wavestack.figures import DPI, FIT_FIGURE_INCHES


def _surface_map(tmp_path: Path, size: int = 96) -> tuple[Path, np.ndarray, np.ndarray]:
    """A disk: 100 nm of sphere, 30 nm of astigmatism and a 2 nm ripple of 8 px period, in nm."""
    rows, cols = np.indices((size, size))
    x, y = (cols - (size - 1) / 2) / 45, ((size - 1) / 2 - rows) / 45
    disk = x * x + y * y <= 1
    surface = 100 * (x * x + y * y) + 30 * (x * x - y * y) + 2 * np.sin(2 * np.pi * cols / 8)
    path = tmp_path / "surface.npy"
    np.save(path, np.where(disk, surface, np.nan))
    return path, disk, surface


def _report(capsys, *argv: str) -> dict:
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _one_line_error(capsys, *argv: str) -> str:
    """The one line of a refused command; a value argparse refuses exits from the parser (status 2)."""
    try:
        status = main(list(argv))
    except SystemExit as exit_:
        status = exit_.code
    assert status == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and "Traceback" not in captured.err
    return captured.err


def test_fit_reports_the_form_figures_pvr_and_the_drawings_verdict(capsys, tmp_path) -> None:
    path, disk, surface = _surface_map(tmp_path)
    report = _report(capsys, "fit", str(path), "--map-unit", "nm", "--spec", "3/1(0.1/0.05; RMSi < 0.05)",
                     "--modes", "15")
    figures = report["surface"]
    # astigmatism is the irregularity: its PV over the disk is 60 nm (+ the ripple), SAG the sphere
    assert figures["form"]["nm"]["SAG"] == pytest.approx(100.0, abs=1.0)
    assert 55.0 < figures["form"]["nm"]["IRR"] < 70.0 and figures["form"]["nm"]["RSI"] < 2.0
    spec = figures["spec"]
    assert [c["quantity"] for c in spec["checks"]] == ["SAG", "IRR", "RSI", "RMSi"]
    assert spec["passed"] is False and spec["limiting"] == "IRR"  # 0.2 fringes against 0.1
    assert figures["pvr"]["nm"] == pytest.approx(figures["pvr"]["fit_pv_nm"] + 3 * figures["pvr"]["residual_rms_nm"])
    text_argv = ["fit", str(path), "--map-unit", "nm", "--spec", "3/1(0.1/0.05)", "--modes", "15"]
    assert main(text_argv) == 0
    text = capsys.readouterr().out
    assert "spec        3/1(0.1/0.05): FAIL (limiting IRR)" in text and "PVr" in text


def test_psd_slope_and_filter_with_the_pixel_pitch(capsys, tmp_path) -> None:
    path, _, _ = _surface_map(tmp_path)
    report = _report(capsys, "fit", str(path), "--map-unit", "um", "--pixel-mm", "0.1", "--psd-band-mm", "0.5,1.6",
                     "--slope-length-mm", "0.5", "--filter", "hp:2", "--modes", "15")["surface"]
    # the map was in um: 1000 times the nm figures
    assert report["form"]["nm"]["SAG"] == pytest.approx(100e3, rel=0.01)
    psd = report["psd"]
    assert psd["band_per_mm"] == pytest.approx([0.625, 2.0])
    # the ripple (2000 nm amplitude, 0.8 mm period) is the band's content: RMS 2000 / sqrt 2 (the
    # sphere and astigmatism have some of theirs there too: 2 % more)
    assert psd["band_rms_nm"] == pytest.approx(2000 / np.sqrt(2), rel=0.05)
    assert report["slope"]["integration_length_mm"] == 0.5 and report["slope"]["rms_urad"] > 0
    assert report["filtered"]["kind"] == "hp" and report["filtered"]["cutoffs_mm"] == [2.0]


@require_shared_data()
def test_analyze_a_measured_map_uses_its_own_pitch_and_reports_pvr_beside_pv(capsys) -> None:
    path = DATA / "zygo-dat" / "valid_zygo_dat_file.dat"
    report = _report(capsys, "analyze", str(path), "--spec", "3/1(0.5/0.2) lambda = 632.8 nm",
                     "--slope-length-mm", "1", "--no-clip")  # the file's every pixel, as it holds them
    surface = report["surface"]
    assert surface["form"]["wavelength_nm"] == 632.8
    assert surface["form"]["nm"]["PV"] == pytest.approx(report["pv_nm"], rel=1e-6)  # the file's own nm
    assert surface["pvr"]["nm"] == pytest.approx(403.12, abs=0.01)
    assert surface["slope"]["samples"][0] > 100000  # the file's 0.118 mm pitch: 1 mm is 8.5 pixels
    assert surface["spec"]["passed"] is False


def test_plot_adds_the_psd_slope_and_filter_panels(capsys, tmp_path) -> None:
    path, _, _ = _surface_map(tmp_path)
    out = tmp_path / "fit.png"
    assert main(["fit", str(path), "--map-unit", "nm", "--pixel-mm", "0.1", "--psd", "--slope-length-mm", "0.5",
                 "--filter", "bp:0.3,3", "--modes", "15", "--plot", str(out)]) == 0
    capsys.readouterr()
    height, width = matplotlib.image.imread(out).shape[:2]
    assert width == round(FIT_FIGURE_INCHES[0] * DPI) and height > round(FIT_FIGURE_INCHES[1] * DPI)


@pytest.mark.parametrize(("extra", "fragment"), [
    (["--spec", "3/2(x)"], "argument --spec: tolerance '3/2(x)': at character 5, expected the irregularity"),
    (["--spec", "3/-(-/-)"], "nothing is toleranced"),
    (["--psd-band-mm", "0.05,4"], "--psd-band-mm: PSD band 0.25-20 cycles/mm (periods 0.05-4 mm): the sampling "
                                  "resolves 0.1111-5 cycles/mm"),
    (["--slope-length-mm", "0.15"], "--slope-length-mm: slope integration length 0.15 mm is 1.5 pixels of 0.1 mm; "
                                    "expected at least 2 pixels (0.2 mm)"),
    (["--filter", "lp:20"], "--filter: filter lp:20: cut-off 20 mm is outside what the sampling resolves"),
    (["--filter", "lp"], "argument --filter: filter 'lp': expected lp:CUTOFF_MM"),
    (["--psd-band-mm", "1"], "argument --psd-band-mm: expected two different spatial periods in mm"),
])
def test_bad_surface_input_is_one_line_naming_the_option(capsys, tmp_path, extra, fragment) -> None:
    path, _, _ = _surface_map(tmp_path)
    err = _one_line_error(capsys, "fit", str(path), "--map-unit", "nm", "--pixel-mm", "0.1", "--modes", "15", *extra)
    assert fragment in err


def test_a_map_without_a_unit_or_a_pitch_says_what_is_missing(capsys, tmp_path) -> None:
    path, _, _ = _surface_map(tmp_path)
    assert "expected --map-unit nm or um" in _one_line_error(capsys, "fit", str(path), "--spec", "3/1")
    assert "--pixel-mm: pixel size: the PSD, slopes and filters need the pixel pitch" in _one_line_error(
        capsys, "fit", str(path), "--map-unit", "nm", "--psd")
    assert "the bundled example is a wavefront in waves" in _one_line_error(capsys, "fit", "--example", "--spec", "3/1")
    # without surface options a .npy of unknown unit is fitted as before, without figures
    assert "surface" not in _report(capsys, "fit", str(path), "--modes", "15")


def test_surface_options_do_not_apply_to_a_spot_image(capsys, tmp_path) -> None:
    err = _one_line_error(capsys, "analyze", str(tmp_path / "spots.png"), "--reference", str(tmp_path / "ref.png"),
                          "--spec", "3/1")
    assert "apply to interferograms and measured maps, not to a Shack-Hartmann spot image" in err
