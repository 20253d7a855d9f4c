"""The calibration file: a self-describing HDF5 file with a content hash; damaged, tampered or foreign files refused."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.pipeline import InputError
from wavestack.pipeline.calibration import CalibrationRefused, ReferenceCalibration, read_calibration, write_calibration

GRID = (40, 48)


def _calibration() -> ReferenceCalibration:
    rows, cols = np.indices(GRID)
    disk = (rows - 20.0) ** 2 + (cols - 24.0) ** 2 <= 18.0**2
    mask = (rows - 20.0) ** 2 + (cols - 24.0) ** 2 <= 16.0**2
    reference = np.where(disk, 0.01 * (cols - 24.0) / 18.0, np.nan)
    return ReferenceCalibration(
        method="rotation", positions=4, date_utc="2026-11-28T14:00:00+00:00", wavelength_nm=632.8, grid=GRID,
        pupil=(24.0, 20.0, 18.0), modes=((0, 0), (1, 1), (1, -1)), unresolved_orders=(0, 4), mask=mask,
        coefficients=np.array([0.0, 0.01, 0.0]), covariance=1e-8 * np.eye(3), reference_waves=reference,
        reference_stderr_waves=np.where(disk, 1e-4, np.nan))


def test_a_written_calibration_reads_back_whole_with_its_hash(tmp_path: Path) -> None:
    written = write_calibration(tmp_path / "cal.h5", _calibration())
    read = read_calibration(tmp_path / "cal.h5")
    assert len(read.digest) == 64 and read.digest == written.digest
    assert (read.method, read.positions, read.grid, read.modes, read.unresolved_orders) == \
        ("rotation", 4, GRID, ((0, 0), (1, 1), (1, -1)), (0, 4))
    assert np.array_equal(read.reference_waves, written.reference_waves, equal_nan=True)
    assert np.array_equal(read.mask, written.mask)
    with pytest.raises(InputError, match="never overwritten"):
        write_calibration(tmp_path / "cal.h5", _calibration())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal.h5"]  # no partial file left


def test_a_tampered_or_truncated_file_is_refused_by_its_hash(tmp_path: Path) -> None:
    path = tmp_path / "cal.h5"
    write_calibration(path, _calibration())
    tampered = tmp_path / "tampered.h5"
    tampered.write_bytes(path.read_bytes())
    with h5py.File(tampered, "r+") as file:
        file["coefficients"][1] = 0.02  # a "better" reference, written by hand
    with pytest.raises(CalibrationRefused, match="tampered.h5: its content hashes to .* changed or damaged"):
        read_calibration(tampered)
    relabelled = tmp_path / "relabelled.h5"
    relabelled.write_bytes(path.read_bytes())
    with h5py.File(relabelled, "r+") as file:
        file.attrs["wavelength_nm"] = 543.5
    with pytest.raises(CalibrationRefused, match="changed or damaged"):
        read_calibration(relabelled)
    cut = tmp_path / "cut.h5"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CalibrationRefused, match="cut.h5"):
        read_calibration(cut)
    with pytest.raises(CalibrationRefused, match="no such file"):
        read_calibration(tmp_path / "missing.h5")


def test_the_correction_is_refused_for_another_grid_aperture_or_wavelength() -> None:
    calibration = _calibration()
    assert np.array_equal(calibration.correction(calibration.mask), calibration.reference_waves, equal_nan=True)
    with pytest.raises(CalibrationRefused, match="40 x 48 camera grid, the frames are 64 x 64"):
        calibration.check_measurement((64, 64))
    with pytest.raises(CalibrationRefused, match="measured at 632.8 nm, the station measures at 543.5 nm"):
        calibration.check_measurement(GRID, 543.5)
    shifted = np.roll(calibration.mask, 6, axis=1)  # the part moved: pixels off the calibrated disk
    with pytest.raises(CalibrationRefused, match="not the calibrated one"):
        calibration.correction(shifted)
    with pytest.raises(CalibrationRefused, match="fit grid"):
        calibration.correction(calibration.mask[::2, ::2])  # a decimated grid asked at step 1
    assert calibration.correction(calibration.mask[::2, ::2], 2).shape == (20, 24)
