"""Measured maps from instrument files, whatever the instrument, and what is not supported.

A measured map carries its own validity: the instrument marked the pixels it could not measure,
and :class:`MeasuredMap` keeps that mask as the file gives it (``valid``), so that a fit can use
exactly those pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from .datx import read_datx
from .errors import InputError
from .fourd import read_4d
from .metropro import read_metropro_dat

__all__ = ["MAX_MAP_MAGNITUDE", "MEASURED_MAP_SUFFIXES", "SUPPORTED_FILES", "MeasuredMap", "check_magnitude",
           "read_measured_map", "unsupported_reason"]

MEASURED_MAP_SUFFIXES = (".dat", ".datx", ".h5")
SUPPORTED_FILES = ".npy, .dat, .datx, 4D .h5, or images"
_IMAGE_SUFFIXES = frozenset({".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp"})
# Kinds of file users try that wavestack does not read, named so the message says what they are.
_KNOWN_UNSUPPORTED = MappingProxyType({
    ".mat": "MATLAB files", ".hdf5": "generic HDF5 files", ".hdf": "generic HDF files",
    ".fits": "FITS files", ".fit": "FITS files", ".csv": "CSV files", ".txt": "text files",
    ".asc": "ASCII files", ".xyz": "XYZ point files", ".npz": ".npz archives", ".4d": ".4D files",
    ".opd": "Wyko .opd files", ".sdf": "surface data files",
})


# A map value beyond this magnitude (in any unit: nm, waves, metres) is not a measurement; its
# square still fits float64 many times over, so the fit's sums stay finite.
MAX_MAP_MAGNITUDE = 1e15



@dataclass(frozen=True, eq=False)
class MeasuredMap:
    """A map measured by an instrument, with the file's own validity.

    Attributes
    ----------
    map_nm : NDArray[np.float64], shape (rows, cols)
        The map in nanometres, NaN exactly where ``valid`` is False. Read-only.
    valid : NDArray[np.bool_], shape (rows, cols)
        The pixels the file holds a measurement for. Read-only.
    wavelength_nm : float or None
        The measurement wavelength, None when the file does not give one.
    pixel_size_m : float or None
        Metres per pixel, None when the file does not say.
    kind : str
        ``"zygo-dat"``, ``"zygo-datx"`` or ``"4d-h5"``.
    """

    map_nm: NDArray[np.float64]
    valid: NDArray[np.bool_]
    wavelength_nm: float | None
    pixel_size_m: float | None
    kind: str

    @property
    def measured_pixels(self) -> int:
        """Number of pixels with a measurement."""
        return int(np.count_nonzero(self.valid))


def unsupported_reason(path: str | Path, *, images: bool = True) -> str | None:
    """The one-line message for a file kind wavestack cannot read, or None if it may read it.

    Parameters
    ----------
    path : str or Path
    images : bool
        Whether images are accepted where the file is used (``analyze``: yes; a map: no).

    Returns
    -------
    str or None
        "<path>: <kind> are not supported; expected ..." for an unsupported suffix.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".npy", *MEASURED_MAP_SUFFIXES) or (images and suffix in _IMAGE_SUFFIXES):
        return None
    what = _KNOWN_UNSUPPORTED.get(suffix, f"'{suffix}' files" if suffix else "files without an extension")
    expected = SUPPORTED_FILES if images else ".npy, .dat, .datx, or 4D .h5"
    return f"{path}: {what} are not supported; expected {expected}"


def read_measured_map(path: str | Path) -> MeasuredMap:
    """Read an instrument's map: Zygo MetroPro ``.dat``, Zygo Mx ``.datx``, 4D 4Sight ``.h5``.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    MeasuredMap

    Raises
    ------
    InputError
        For an unsupported suffix (said first), an unreadable file, a file without a valid
        pixel, or a value beyond ``MAX_MAP_MAGNITUDE`` nanometres.

    Examples
    --------
    >>> from wavestack.pipeline.formats import read_measured_map
    >>> read_measured_map("scan.mat")
    Traceback (most recent call last):
    ...
    wavestack.pipeline.formats.errors.InputError: scan.mat: MATLAB files are not supported; expected .npy, .dat, .datx, 4D .h5, or images
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MEASURED_MAP_SUFFIXES:
        raise InputError(unsupported_reason(path) or f"{path}: expected a measured map (.dat, .datx or 4D .h5)")
    if suffix == ".dat":
        data = read_metropro_dat(path)
        map_nm, wavelength, pixel = data.phase_nm, data.header.wavelength_nm, data.header.lateral_resolution_m
        kind = "zygo-dat"
    elif suffix == ".datx":
        datx = read_datx(path)
        map_nm, wavelength, pixel, kind = datx.surface_nm, datx.wavelength_nm, datx.lateral_resolution_m, "zygo-datx"
    else:
        fourd = read_4d(path)
        map_nm, wavelength, pixel, kind = fourd.map_nm, fourd.wavelength_nm, fourd.pixel_size_m, "4d-h5"
    valid = np.isfinite(map_nm)
    if not valid.any():
        raise InputError(f"{path}: no valid pixel; expected a map with measured pixels")
    check_magnitude(path, map_nm[valid])
    valid.flags.writeable = False
    return MeasuredMap(map_nm=map_nm, valid=valid, wavelength_nm=wavelength, pixel_size_m=pixel, kind=kind)


def check_magnitude(path: str | Path, values: NDArray[np.float64]) -> None:
    """Refuse map values beyond :data:`MAX_MAP_MAGNITUDE` (finite values only).

    Raises
    ------
    InputError
        Naming the file, the largest magnitude and the bound.
    """
    largest = float(np.max(np.abs(values))) if values.size else 0.0
    if largest > MAX_MAP_MAGNITUDE:
        raise InputError(f"{path}: a value of magnitude {largest:.3g} is not a measurement; expected map values "
                         f"within +-{MAX_MAP_MAGNITUDE:g}")
