"""A stored calibration of the reference: the value, its HDF5 file with a content hash, and the correction it gives.

:class:`ReferenceCalibration` is what a calibration measured about the instrument's reference:
its error as circle Zernike coefficients over a pupil on the camera grid (waves of wavefront, at
``wavelength_nm``), the same as a map over the pupil's disk, their uncertainty, the aperture it was
measured on, and what the method could not separate. Every measurement subtracts
:meth:`ReferenceCalibration.correction` from its unwrapped map before the fit.

The file (``write_calibration``, ``read_calibration``) is HDF5 written through h5py, self-describing:
attributes ``format = "wavestack-calibration"``, ``version``, ``method``, ``positions``,
``date_utc``, ``wavelength_nm``, ``grid``, ``pupil``, ``modes`` (n, m rows), ``unresolved_orders``,
``content_sha256``; datasets ``mask`` (uint8), ``coefficients``, ``covariance``,
``reference_waves``, ``reference_stderr_waves``. ``content_sha256`` is the SHA-256 of the content
in a fixed order (:func:`content_digest`): the attributes as sorted JSON, then each dataset's name,
dtype, shape and bytes. A file whose content does not hash to its stored digest, or that cannot be
read whole (truncated), is refused (:class:`CalibrationRefused`, with the reason). The file is
written to a temporary name beside the target and renamed, so a crash never leaves half a
calibration under the name.

The correction is refused, never resampled, when the measurement's grid or wavelength is not the
calibration's, or its aperture is not the one calibrated (fewer than 99.5 % of its pixels on the
calibration's disk, or an intersection over union with the calibrated aperture below 0.9).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
from numpy.typing import NDArray

from ..formats import InputError, open_hdf5_readonly

__all__ = ["CalibrationRefused", "FORMAT", "ReferenceCalibration", "content_digest", "read_calibration",
           "write_calibration"]

FORMAT = "wavestack-calibration"
VERSION = 1
MIN_ON_DISK = 0.995  # of a measurement's aperture pixels on the calibration's disk
MIN_IOU = 0.9  # of a measurement's aperture with the calibrated one
_DATASETS = ("mask", "coefficients", "covariance", "reference_waves", "reference_stderr_waves")


class CalibrationRefused(ValueError):
    """A calibration that cannot be used here: damaged, or measured for another grid, aperture or wavelength."""


@dataclass(frozen=True, eq=False)
class ReferenceCalibration:
    """The reference's error as a calibration measured it (module notes).

    Attributes
    ----------
    method : str
        ``"rotation"`` (the N-position test) or another absolute test.
    positions : int
        N, the measurements combined.
    date_utc : str
        ISO 8601 time of the calibration.
    wavelength_nm : float
    grid : (int, int)
        Camera rows and columns.
    pupil : (float, float, float)
        The basis's unit disk ``(cx, cy, radius)``, pixels.
    modes : tuple of (n, m)
        The circle Zernike terms (Noll order, unit RMS) of ``coefficients``.
    unresolved_orders : tuple of int
        Angular orders the method could not separate (not in the calibration).
    mask : ndarray of bool, shape grid
        The aperture the calibration was measured on.
    coefficients : ndarray, shape (M,)
        The reference's error, waves of wavefront.
    covariance : ndarray, shape (M, M)
        Their covariance, waves squared.
    reference_waves, reference_stderr_waves : ndarray, shape grid
        The error and its standard error per pixel over the pupil's disk, waves (NaN outside).
    digest : str
        ``content_sha256`` (hex): what results and recordings name.
    """

    method: str
    positions: int
    date_utc: str
    wavelength_nm: float
    grid: tuple[int, int]
    pupil: tuple[float, float, float]
    modes: tuple[tuple[int, int], ...]
    unresolved_orders: tuple[int, ...]
    mask: NDArray[np.bool_]
    coefficients: NDArray[np.float64]
    covariance: NDArray[np.float64]
    reference_waves: NDArray[np.float64]
    reference_stderr_waves: NDArray[np.float64]
    digest: str = ""

    def attributes(self) -> dict[str, object]:
        """The file's attributes (JSON-ready, without the digest)."""
        return {"format": FORMAT, "version": VERSION, "method": self.method, "positions": int(self.positions),
                "date_utc": self.date_utc, "wavelength_nm": float(self.wavelength_nm),
                "grid": [int(v) for v in self.grid], "pupil": [float(v) for v in self.pupil],
                "modes": [[int(n), int(m)] for n, m in self.modes],
                "unresolved_orders": [int(v) for v in self.unresolved_orders]}

    def arrays(self) -> dict[str, NDArray]:
        """The file's datasets, in their stored types."""
        return {"mask": self.mask.astype(np.uint8), "coefficients": np.asarray(self.coefficients, np.float64),
                "covariance": np.asarray(self.covariance, np.float64),
                "reference_waves": np.asarray(self.reference_waves, np.float64),
                "reference_stderr_waves": np.asarray(self.reference_stderr_waves, np.float64)}

    def check_measurement(self, grid: tuple[int, int], wavelength_nm: float | None = None) -> None:
        """Refuse a measurement of another camera grid or wavelength.

        Raises
        ------
        CalibrationRefused
            Naming the calibration's value and the measurement's.
        """
        if tuple(int(v) for v in grid) != tuple(self.grid):
            raise CalibrationRefused(f"calibration {self.digest[:12]}: measured on a {self.grid[0]} x {self.grid[1]} "
                                     f"camera grid, the frames are {grid[0]} x {grid[1]}; never resampled")
        if wavelength_nm is not None and abs(wavelength_nm - self.wavelength_nm) > 1e-6 * self.wavelength_nm:
            raise CalibrationRefused(f"calibration {self.digest[:12]}: measured at {self.wavelength_nm:g} nm, "
                                     f"the station measures at {wavelength_nm:g} nm")

    def correction(self, aperture: NDArray[np.bool_], step: int = 1) -> NDArray[np.float64]:
        """The map to subtract from a measurement on ``aperture`` (the fit grid, every ``step``-th pixel), waves.

        Parameters
        ----------
        aperture : ndarray of bool, shape (ceil(rows / step), ceil(cols / step))
            The measurement's fitted aperture on its fit grid.
        step : int
            The fit grid's decimation.

        Returns
        -------
        ndarray of float64, the shape of ``aperture``
            The reference's error there (NaN off the calibration's disk).

        Raises
        ------
        CalibrationRefused
            Another grid, or not the calibrated aperture (module notes).
        """
        reference = self.reference_waves[::step, ::step]
        if reference.shape != aperture.shape:
            raise CalibrationRefused(f"calibration {self.digest[:12]}: the fit grid is {aperture.shape}, the "
                                     f"calibration's at step {step} is {reference.shape}; never resampled")
        pixels = int(aperture.sum())
        on_disk = float(np.isfinite(reference[aperture]).mean()) if pixels else 0.0
        calibrated = self.mask[::step, ::step]
        iou = float((aperture & calibrated).sum() / max(int((aperture | calibrated).sum()), 1))
        if on_disk < MIN_ON_DISK or iou < MIN_IOU:
            raise CalibrationRefused(
                f"calibration {self.digest[:12]}: the aperture is not the calibrated one ({100 * on_disk:.1f} % of "
                f"its pixels on the calibration's disk, IoU {iou:.3f} with the calibrated aperture; expected >= "
                f"{100 * MIN_ON_DISK:.1f} % and >= {MIN_IOU})")
        return reference

    def summary(self) -> dict[str, object]:
        """JSON-ready: what a result names (the digest) and what the calibration is."""
        return {"sha256": self.digest, "method": self.method, "positions": self.positions, "date_utc": self.date_utc,
                "unresolved_orders": list(self.unresolved_orders)}


def content_digest(attributes: dict[str, object], arrays: dict[str, NDArray]) -> str:
    """SHA-256 (hex) of a calibration's content in its fixed order (module notes)."""
    digest = hashlib.sha256(json.dumps(attributes, sort_keys=True, separators=(",", ":")).encode())
    for name in _DATASETS:
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def write_calibration(path: str | Path, calibration: ReferenceCalibration) -> ReferenceCalibration:
    """Write the calibration file (module notes); returns the calibration with its digest.

    Raises
    ------
    InputError
        The file exists already, or cannot be written; the message names it.
    """
    path = Path(path)
    if path.exists():
        raise InputError(f"{path}: exists already; a calibration file is never overwritten")
    attributes, arrays = calibration.attributes(), calibration.arrays()
    digest = content_digest(attributes, arrays)
    partial = path.with_name(f".{path.name}.partial")
    try:
        with h5py.File(partial, "w-") as file:
            for key, value in attributes.items():
                file.attrs[key] = json.dumps(value) if isinstance(value, (list, dict)) else value
            file.attrs["content_sha256"] = digest
            for name in _DATASETS:
                file.create_dataset(name, data=arrays[name], fletcher32=True)
        os.replace(partial, path)
    except OSError as error:
        partial.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write the calibration: {error}") from None
    return _with_digest(calibration, digest)


def read_calibration(path: str | Path) -> ReferenceCalibration:
    """Read and check a calibration file.

    Raises
    ------
    CalibrationRefused
        Not a calibration file, truncated or unreadable, or its content does not hash to its
        stored ``content_sha256`` (changed or damaged); the message names the file and the reason.
    """
    path = Path(path)
    try:
        opened = open_hdf5_readonly(path)
    except InputError as error:
        raise CalibrationRefused(f"calibration {error}") from None
    try:
        with opened.file as file:
            if opened.truncated:
                raise CalibrationRefused(f"{path}: truncated ({opened.file_bytes} of {opened.expected_bytes} bytes)")
            if file.attrs.get("format") != FORMAT:
                raise CalibrationRefused(f"{path}: not a wavestack calibration (attribute format = "
                                         f"{file.attrs.get('format')!r})")
            attributes = {key: _attribute(file.attrs[key]) for key in file.attrs if key != "content_sha256"}
            stored = str(file.attrs.get("content_sha256", ""))
            arrays = {name: np.asarray(file[name]) for name in _DATASETS}
    except CalibrationRefused:
        raise
    except (OSError, KeyError, ValueError, TypeError) as error:
        raise CalibrationRefused(f"{path}: cannot be read whole ({type(error).__name__}: {error}); expected a "
                                 "complete wavestack calibration") from None
    computed = content_digest(attributes, arrays)
    if computed != stored:
        raise CalibrationRefused(f"{path}: its content hashes to {computed[:12]}, the file says {stored[:12] or 'nothing'}: "
                                 "changed or damaged since it was written")
    return ReferenceCalibration(
        method=str(attributes["method"]), positions=int(attributes["positions"]), date_utc=str(attributes["date_utc"]),
        wavelength_nm=float(attributes["wavelength_nm"]), grid=tuple(attributes["grid"]),
        pupil=tuple(attributes["pupil"]), modes=tuple(tuple(v) for v in attributes["modes"]),
        unresolved_orders=tuple(attributes["unresolved_orders"]), mask=arrays["mask"].astype(bool),
        coefficients=arrays["coefficients"], covariance=arrays["covariance"],
        reference_waves=arrays["reference_waves"], reference_stderr_waves=arrays["reference_stderr_waves"],
        digest=stored)


def _attribute(value: object) -> object:
    """An attribute as written: lists and dicts were stored as JSON text, numbers and words as themselves."""
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, str) and value[:1] in "[{":
        return json.loads(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def _with_digest(calibration: ReferenceCalibration, digest: str) -> ReferenceCalibration:
    values = {name: getattr(calibration, name) for name in ReferenceCalibration.__dataclass_fields__}
    values["digest"] = digest
    return ReferenceCalibration(**values)
