"""4D Technology 4Sight .h5 files, measured maps from any instrument, and files that are not
supported."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.pipeline import InputError, load_map, read_4d, read_measured_map, read_metropro_dat

from shared_data import DATA, require_shared_data

_MARKER = np.float32(3.4028235e38)  # 4Sight's invalid-pixel marker (the largest float32)


def _opd_waves() -> np.ndarray:
    """A 20 x 30 OPD map in waves: tilt and defocus, with markers and one NaN."""
    rows, cols = np.mgrid[:20, :30].astype(np.float64)
    waves = (0.01 * cols - 0.02 * rows + 0.3 * ((cols - 15) ** 2 + (rows - 10) ** 2) / 200).astype(np.float32)
    waves[0, :3] = _MARKER
    waves[19, 29] = _MARKER
    waves[5, 5] = np.nan
    return waves


def write_genraw(path: Path, waves: np.ndarray, wavelength: str = "632.8 nm", xpix: str | None = "0.125 mm") -> None:
    """A 4Sight .h5 file in the layout open readers document: measurement0/genraw."""
    with h5py.File(path, "w") as h5:
        genraw = h5.create_group("measurement0/genraw")
        genraw.attrs["wavelength"] = wavelength
        if xpix is not None:
            genraw.attrs["xpix"] = xpix
        genraw.create_dataset("data", data=waves)


def test_genraw_layout_map_wavelength_pixel_size_and_markers(tmp_path: Path) -> None:
    waves = _opd_waves()
    path = tmp_path / "m.h5"
    write_genraw(path, waves)
    result = read_4d(path)
    invalid = (waves == _MARKER) | np.isnan(waves)  # counted from the array we wrote
    assert result.wavelength_nm == pytest.approx(632.8)
    assert result.pixel_size_m == pytest.approx(0.125e-3)
    assert np.array_equal(np.isnan(result.map_nm), invalid)
    # waves to nm by the wavelength; float32 storage limits agreement to ~1e-7 relative
    np.testing.assert_allclose(result.map_nm[~invalid], waves[~invalid].astype(np.float64) * 632.8, rtol=1e-6)


def test_surface_in_waves_layout(tmp_path: Path) -> None:
    waves = np.where(_opd_waves() == _MARKER, np.nan, _opd_waves())
    path = tmp_path / "s.h5"
    with h5py.File(path, "w") as h5:
        h5.create_dataset("Measurement/SurfaceInWaves/Data", data=waves)
        h5["Measurement"].attrs["WavelengthInNanometers"] = 543.5
    result = read_4d(path)
    assert result.wavelength_nm == 543.5 and result.pixel_size_m is None
    assert np.array_equal(np.isnan(result.map_nm), np.isnan(waves))


def test_uncalibrated_file_has_no_pixel_size(tmp_path: Path) -> None:
    path = tmp_path / "u.h5"
    write_genraw(path, _opd_waves(), xpix=None)
    assert read_4d(path).pixel_size_m is None


def test_bad_wavelength_attribute_is_named(tmp_path: Path) -> None:
    path = tmp_path / "w.h5"
    write_genraw(path, _opd_waves(), wavelength="red")
    with pytest.raises(InputError, match=r"w\.h5: attribute 'wavelength' = 'red'"):
        read_4d(path)


def test_unknown_hdf5_layout_says_so(tmp_path: Path) -> None:
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as h5:
        h5.create_dataset("images/frame0", data=np.zeros((4, 4)))
    with pytest.raises(InputError, match=r"other\.h5: an HDF5 file of unknown layout \(top level: images\)"):
        read_measured_map(path)
    with pytest.raises(InputError, match="unknown layout"):
        load_map(path)


def test_load_map_reads_a_4d_file_in_nanometres(tmp_path: Path) -> None:
    waves = _opd_waves()
    path = tmp_path / "m.h5"
    write_genraw(path, waves)
    loaded = load_map(path)
    valid = ~((waves == _MARKER) | np.isnan(waves))
    np.testing.assert_allclose(loaded[valid], waves[valid].astype(np.float64) * 632.8, rtol=1e-6)
    assert np.isnan(loaded[~valid]).all()


@pytest.mark.parametrize(
    ("name", "kind"),
    [("scan.mat", "MATLAB files"), ("scan.xyz", "XYZ point files"), ("scan.foo", "'.foo' files")],
)
def test_unsupported_files_say_so_first(tmp_path: Path, name: str, kind: str) -> None:
    path = tmp_path / name
    path.write_bytes(b"\x00" * 16)
    with pytest.raises(InputError) as caught:
        load_map(path)
    assert str(caught.value).startswith(f"{path}: {kind} are not supported; expected .npy, .dat")
    with pytest.raises(InputError, match=f"{kind} are not supported"):
        read_measured_map(path)


@require_shared_data()
def test_zygo_validity_is_the_files_own() -> None:
    path = DATA / "zygo-dat" / "valid_zygo_dat_file.dat"
    measured = read_measured_map(path)
    phase = read_metropro_dat(path).phase_nm
    assert measured.kind == "zygo-dat" and measured.wavelength_nm == pytest.approx(632.8, rel=1e-6)
    assert np.array_equal(measured.valid, np.isfinite(phase))
    assert measured.measured_pixels == int(np.isfinite(phase).sum())
