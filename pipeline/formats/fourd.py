"""Reader for 4D Technology 4Sight ``.h5`` measurement files (HDF5).

No specification from 4D Technology was available; the layouts read here are those that
open-source readers of 4Sight files agree on (they read the same paths and attributes), and
they were checked only against files our tests write from that description:

``measurement0/genraw`` (4Sight's own ``.h5`` export)
    * ``measurement0/genraw/data``: 2-D OPD map in waves, rows first as stored;
    * attribute ``wavelength`` on ``genraw``: text "<value> <unit>", e.g. ``"632.8 nm"``;
    * attribute ``xpix`` on ``genraw``: the pixel size as text "<value> <unit>", e.g.
      ``"0.125 mm"``; absent or unparsable in uncalibrated files (then ``None``);
    * invalid pixels carry a huge marker value. Open readers detect it either as
      "the largest value in the map" or as "above 1e10"; the first would discard the highest
      measured pixel of a map without invalid pixels, so this reader uses the second, as
      ``|value| > 1e10`` waves (no interferometer reports ten billion waves), plus any non-finite
      value.

``Measurement/SurfaceInWaves`` (4Sight/PhaseCam ``.4D``-style files)
    * ``Measurement/SurfaceInWaves/Data``: 2-D surface map in waves, NaN where invalid;
    * attribute ``WavelengthInNanometers`` on ``Measurement``;
    * no pixel size is read (the readers do not agree on one).

The map is returned in nanometres (waves times the wavelength); for the genraw layout that is
the optical path difference the file holds, for SurfaceInWaves the surface.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from .errors import InputError
from .hdf5_checks import check_dataset_size
from .hdf5_guard import DEFAULT_TIMEOUT_S, read_guarded

__all__ = ["FourDMap", "is_4d_file", "read_4d"]

INVALID_ABOVE_WAVES = 1e10  # |value| above this (waves) is the invalid marker
_GENRAW = "measurement0/genraw"
_SURFACE = "Measurement/SurfaceInWaves"
_NM_PER_UNIT = MappingProxyType({"m": 1e9, "mm": 1e6, "um": 1e3, "µm": 1e3, "nm": 1.0})
_QUANTITY = re.compile(r"^\s*([-+0-9.eE]+)\s*([a-zA-Zµ]*)\s*$")


@dataclass(frozen=True, eq=False)
class FourDMap:
    """A map read from a 4D Technology 4Sight ``.h5`` file.

    Attributes
    ----------
    map_nm : NDArray[np.float64], shape (rows, cols)
        The measured map in nanometres, NaN where the file marks a pixel invalid. Read-only.
    wavelength_nm : float
        The measurement wavelength, in nanometres.
    pixel_size_m : float or None
        Metres per pixel, or None when the file does not say.
    layout : str
        ``"measurement0/genraw"`` or ``"Measurement/SurfaceInWaves"``.
    """

    map_nm: NDArray[np.float64]
    wavelength_nm: float
    pixel_size_m: float | None
    layout: str


def _text(value: Any) -> str:
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(-1)[0]
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace")
    return str(value)


def _nanometres(path: Path, name: str, value: Any, default_unit: str) -> float:
    """An attribute "<value> <unit>" (or a bare number in ``default_unit``) in nanometres."""
    match = _QUANTITY.match(_text(value))
    unit = (match.group(2) if match else "") or default_unit
    if match is None or unit.lower() not in _NM_PER_UNIT:
        known = ", ".join(_NM_PER_UNIT)
        raise InputError(f"{path}: attribute {name!r} = {_text(value)!r}; expected '<number> <unit>' "
                         f"with a unit among {known}")
    try:
        return float(match.group(1)) * _NM_PER_UNIT[unit.lower()]
    except ValueError:
        raise InputError(f"{path}: attribute {name!r} = {_text(value)!r} is not a number") from None


def _waves(path: Path, node: Any, max_bytes: int | None) -> NDArray[np.float64]:
    if not isinstance(node, h5py.Dataset):
        raise InputError(f"{path}: expected a dataset for the map, found a group at {node.name}")
    check_dataset_size(path, node, max_bytes)
    waves = node[()].astype(np.float64)
    with np.errstate(invalid="ignore"):
        waves[~(np.abs(waves) <= INVALID_ABOVE_WAVES)] = np.nan
    return waves


def is_4d_file(h5: h5py.File) -> bool:
    """True if the open HDF5 file has one of the 4Sight layouts this module reads."""
    return f"{_GENRAW}/data" in h5 or f"{_SURFACE}/Data" in h5


def _layout_error(path: Path, h5: h5py.File) -> InputError:
    found = ", ".join(sorted(h5.keys())[:8]) or "nothing"
    return InputError(
        f"{path}: an HDF5 file of unknown layout (top level: {found}); expected a 4D Technology "
        f"4Sight file with {_GENRAW}/data or {_SURFACE}/Data"
    )


def read_4d(path: str | Path, *, max_bytes: int | None = None, timeout_s: float = DEFAULT_TIMEOUT_S) -> FourDMap:
    """Read the map, wavelength and pixel size of a 4D Technology 4Sight ``.h5`` file.

    The layouts read are described in the module docstring (:mod:`wavestack.pipeline.formats.fourd`).

    Parameters
    ----------
    path : str or Path
        The ``.h5`` file.
    max_bytes : int, optional
        The most the map may make this reader allocate (default: the memory budget of
        :mod:`wavestack.pipeline.formats.limits`); it must also be stored in full in the file.
    timeout_s : float
        The file is read in a child process that must finish within this time
        (:mod:`wavestack.pipeline.formats.hdf5_guard`): a damaged file can hang the HDF5 library.

    Returns
    -------
    FourDMap
        ``map_nm`` of shape (rows, cols) in nanometres with NaN for invalid pixels.

    Raises
    ------
    InputError
        If the file is missing, not HDF5, of another HDF5 layout (the message lists what it
        holds and what was expected), its map or attributes are malformed, its map is larger
        than the memory budget or than the file's stored bytes justify, or the HDF5 structure
        is damaged (link loops, dangling links, unreadable chunks, a read that hangs or crashes
        the HDF5 library).

    Examples
    --------
    A 2 x 3 map of 0.1 wave with one invalid pixel, in the genraw layout:

    >>> import tempfile, h5py, numpy as np
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "m.h5"
    ...     with h5py.File(path, "w") as h5:
    ...         node = h5.create_group("measurement0/genraw")
    ...         node.attrs["wavelength"] = "632.8 nm"
    ...         data = np.full((2, 3), 0.125, np.float32)
    ...         data[0, 0] = 3.4e38
    ...         _ = node.create_dataset("data", data=data)
    ...     result = read_4d(path)
    >>> int(np.isnan(result.map_nm).sum()), float(np.nanmean(result.map_nm))
    (1, 79.1)
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    fourd = read_guarded(functools.partial(_read_file, max_bytes=max_bytes), path, timeout_s)
    fourd.map_nm.flags.writeable = False  # read-only again after the pipe
    return fourd


def _read_file(path: Path, max_bytes: int | None) -> FourDMap:
    """:func:`read_4d` in the calling process."""
    try:
        h5 = h5py.File(path, "r")
    except OSError:
        raise InputError(f"{path}: not a readable HDF5 file; expected a 4D Technology 4Sight .h5 file") from None
    with h5:
        try:
            wavelength_nm, pixel_size, waves, layout = _read_open(path, h5, max_bytes)
        except InputError:
            raise
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as error:
            raise InputError(f"{path}: damaged 4D (HDF5) structure: {type(error).__name__}: {error}") from None
    if not 1.0 < wavelength_nm < 1e6:
        raise InputError(f"{path}: wavelength {wavelength_nm} nm is not a wavelength")
    if pixel_size is not None and not pixel_size > 0:
        pixel_size = None  # uncalibrated files write 0
    map_nm = waves * wavelength_nm
    map_nm.flags.writeable = False
    return FourDMap(map_nm=map_nm, wavelength_nm=wavelength_nm, pixel_size_m=pixel_size, layout=layout)


def _read_open(path: Path, h5: h5py.File, max_bytes: int | None) -> tuple[float, float | None, NDArray[np.float64], str]:
    """Wavelength (nm), pixel size (m), map (waves) and layout of the open file."""
    if f"{_GENRAW}/data" in h5:
        group = h5[_GENRAW]
        if "wavelength" not in group.attrs:
            raise InputError(f"{path}: {_GENRAW} has no 'wavelength' attribute")
        wavelength_nm = _nanometres(path, "wavelength", group.attrs["wavelength"], "nm")
        pixel = group.attrs.get("xpix")
        pixel_size = _nanometres(path, "xpix", pixel, "mm") * 1e-9 if pixel is not None else None
        waves, layout = _waves(path, group["data"], max_bytes), _GENRAW
    elif f"{_SURFACE}/Data" in h5:
        measurement = h5["Measurement"]
        if "WavelengthInNanometers" not in measurement.attrs:
            raise InputError(f"{path}: Measurement has no 'WavelengthInNanometers' attribute")
        wavelength_nm = _nanometres(path, "WavelengthInNanometers",
                                    measurement.attrs["WavelengthInNanometers"], "nm")
        waves, layout, pixel_size = _waves(path, h5[f"{_SURFACE}/Data"], max_bytes), _SURFACE, None
    else:
        raise _layout_error(path, h5)
    return wavelength_nm, pixel_size, waves, layout
