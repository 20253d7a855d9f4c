"""Reader for Zygo Mx ``.datx`` interferometer files (HDF5).

An HDF5 file; the layout read here is documented in :func:`read_datx`. It was checked only
against synthetic files written by our own tests, never against a file from a Zygo
instrument.

References
----------
.. [1] The HDF Group, *HDF5 User's Guide*; h5py documentation, "Attributes" and "Compound
   types".
"""

from __future__ import annotations

import functools
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

__all__ = ["DatxMap", "read_datx"]


@dataclass(frozen=True, eq=False)
class DatxMap:
    """A surface map read from a Zygo ``.datx`` file.

    Attributes
    ----------
    surface_nm : NDArray[np.float64], shape (rows, cols)
        Surface (or wavefront, as the file defines it) in nanometres, NaN where the file
        marks no data. Read-only.
    intensity : NDArray[np.float64] or None, shape (rows', cols')
        Intensity as stored (no unit conversion), NaN where the file marks no data; None
        when the file has none. Read-only.
    wavelength_nm : float or None
        Wavelength, in nanometres, or None when the file does not give one.
    lateral_resolution_m : float or None
        Metres per pixel along the columns (``X Converter``), or None when not calibrated.
    attributes : dict
        The attributes of the surface dataset, decoded to Python values (bytes to str,
        one-element arrays to scalars, compound values to tuples).
    """

    surface_nm: NDArray[np.float64]
    intensity: NDArray[np.float64] | None
    wavelength_nm: float | None
    lateral_resolution_m: float | None
    attributes: dict[str, Any]


# Length units of a Zygo converter's BaseUnit (matched case-insensitively), in nanometres.
_NM_PER_UNIT = MappingProxyType(
    {
        "meters": 1e9,
        "millimeters": 1e6,
        "micrometers": 1e3,
        "microns": 1e3,
        "nanometers": 1.0,
        "angstroms": 0.1,
        "picometers": 1e-3,
    }
)


# A wavelength in metres outside (1 nm, 1 mm) is not an interferometer's (X-rays to far infrared).
_WAVELENGTH_M = (1e-9, 1e-3)
_GROUPS = ("Measurement", "Data")  # where the Surface and Intensity data are looked for, in order


def _plain(value: Any) -> Any:
    """An HDF5 attribute as a plain Python value: bytes to str, 1-element arrays unwrapped."""
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace")
    if isinstance(value, np.void) and value.dtype.names:
        return tuple(_plain(value[name]) for name in value.dtype.names)
    if isinstance(value, np.ndarray):
        if value.size == 1:
            return _plain(value.reshape(-1)[0])
        if value.dtype.kind in "OSUV":
            return [_plain(item) for item in value.reshape(-1)]
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(item) for item in value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def _converter(path: Path, name: str, value: Any) -> tuple[str, str, tuple[float, ...]]:
    """Decode a Zygo converter attribute to (Category, BaseUnit, Parameters).

    Accepts a compound (structured) array of shape (1,) or (), a compound scalar, or a plain
    sequence ``(category, unit, parameters)``; fields are taken by name (case-insensitive)
    when the compound has names, by position otherwise.
    """
    if isinstance(value, np.ndarray) and value.dtype.names and value.size == 1:
        value = value.reshape(-1)[0]
    if isinstance(value, np.void) and value.dtype.names:
        by_name = {field.lower(): value[field] for field in value.dtype.names}
        keys = ("category", "baseunit", "parameters")
        if all(key in by_name for key in keys):
            fields = [by_name[key] for key in keys]
        else:
            fields = [value[field] for field in value.dtype.names]
    elif isinstance(value, (tuple, list, np.ndarray)) and len(value) >= 3:
        fields = list(value)
    else:
        raise InputError(
            f"{path}: attribute {name!r} is not a (Category, BaseUnit, Parameters) converter"
        )
    if len(fields) < 3:
        raise InputError(
            f"{path}: attribute {name!r} has {len(fields)} fields; "
            "expected Category, BaseUnit, Parameters"
        )
    category, unit = str(_plain(fields[0])), str(_plain(fields[1]))
    try:
        parameters = tuple(float(p) for p in np.asarray(fields[2], dtype=np.float64).reshape(-1))
    except (TypeError, ValueError):
        raise InputError(
            f"{path}: attribute {name!r} has non-numeric Parameters {fields[2]!r}"
        ) from None
    return category, unit, parameters


def _data_node(h5: h5py.File, kind: str) -> h5py.Dataset | None:
    """``<group>/<kind>`` as a dataset, or the only dataset in a group of that name."""
    for group in _GROUPS:
        node = h5.get(f"{group}/{kind}")
        if isinstance(node, h5py.Dataset):
            return node
        if isinstance(node, h5py.Group):
            datasets = [item for item in node.values() if isinstance(item, h5py.Dataset)]
            if len(datasets) == 1:
                return datasets[0]
    return None


def _attribute(node: h5py.Dataset, name: str) -> Any | None:
    """The attribute on the dataset, else on the nearest enclosing group; None if absent."""
    holder: h5py.Dataset | h5py.Group = node
    while True:
        if name in holder.attrs:
            return holder.attrs[name]
        if holder.name == "/":
            return None
        holder = holder.parent


def _masked(path: Path, node: h5py.Dataset, kind: str, max_bytes: int | None) -> NDArray[np.float64]:
    check_dataset_size(path, node, max_bytes)
    raw = node[()]
    values = raw.astype(np.float64)
    no_data = _attribute(node, "No Data")
    invalid = ~np.isfinite(values)
    if no_data is not None:
        try:
            invalid |= raw == float(_plain(no_data))
        except (TypeError, ValueError):
            raise InputError(
                f"{path}: {kind} attribute 'No Data' is not a number: {no_data!r}"
            ) from None
    values[invalid] = np.nan
    return values


def _nm_per_value(path: Path, unit: str, parameters: tuple[float, ...]) -> float:
    key = unit.replace(" ", "").lower()
    if key in _NM_PER_UNIT:
        return _NM_PER_UNIT[key]
    if key in ("fringes", "waves"):
        # Fringes: Parameters (.., wavelength m, S, O); Waves: (.., wavelength m, ...).
        needed = 4 if key == "fringes" else 2
        if (len(parameters) < needed or not all(p > 0 for p in parameters[1:needed])
                or not _WAVELENGTH_M[0] < parameters[1] < _WAVELENGTH_M[1]):
            raise InputError(
                f"{path}: surface in {unit} needs Z Converter Parameters (_, wavelength, S, O) "
                f"with positive values and a wavelength between 1 nm and 1 mm, got {parameters}"
            )
        return float(np.prod(parameters[1:needed])) * 1e9
    known = ", ".join([*_NM_PER_UNIT, "fringes", "waves"])
    raise InputError(f"{path}: unknown surface unit {unit!r}; known (any case): {known}")


def _wavelength_nm(path: Path, node: h5py.Dataset, z_parameters: tuple[float, ...]) -> float | None:
    value = _attribute(node, "Wavelength")
    if value is not None:
        try:
            metres = float(_plain(value))
        except (TypeError, ValueError):
            raise InputError(f"{path}: attribute 'Wavelength' is not a number: {value!r}") from None
        if not _WAVELENGTH_M[0] < metres < _WAVELENGTH_M[1]:
            raise InputError(
                f"{path}: attribute 'Wavelength' = {metres} is not a wavelength in metres"
            )
        return metres * 1e9
    if len(z_parameters) >= 2 and _WAVELENGTH_M[0] < z_parameters[1] < _WAVELENGTH_M[1]:
        return z_parameters[1] * 1e9
    return None


def read_datx(path: str | Path, *, max_bytes: int | None = None, timeout_s: float = DEFAULT_TIMEOUT_S) -> DatxMap:
    """Read the surface (and intensity) of a Zygo Mx ``.datx`` (HDF5) file.

    The layout read, checked only against synthetic files written by our tests (no file from
    a Zygo instrument was available):

    * data: the surface is the dataset ``Measurement/Surface``; where that is a group, the
      only dataset inside it. If there is no ``Measurement/Surface``, ``Data/Surface`` is
      tried the same way (the ``Data/Surface/{id}`` arrangement that public readers of Zygo
      Mx files describe; the ``MetaData`` link table is not read). ``Intensity`` is looked
      for the same way and is optional. Rows are the first index, as stored.
    * attributes, looked up on the dataset, then on its enclosing groups up to the file root:

      - ``No Data``: value (scalar or one-element array) marking pixels without data; those
        pixels, and non-finite ones, become NaN.
      - ``Z Converter``: (Category, BaseUnit, Parameters), stored as a compound array of
        shape (1,) or (), a compound scalar, or a plain sequence; Parameters a variable- or
        fixed-length float array. BaseUnit is the unit of the stored values: Meters,
        MilliMeters, MicroMeters (or Microns), NanoMeters, Angstroms, PicoMeters (any case)
        are scaled to nm; Fringes are converted as ``value * P[1] * P[2] * P[3]`` metres
        (P[1] wavelength in m, P[2] = S, P[3] = O, as in MetroPro); Waves as
        ``value * P[1]``. Without ``Z Converter`` the attribute ``Unit`` (a string) gives the
        unit, and Fringes/Waves cannot be converted.
      - ``Wavelength``: in metres; if absent, ``Z Converter`` Parameters[1] when it lies
        between 1 nm and 1 mm; else None.
      - ``X Converter``: Parameters[1] is the lateral resolution in metres per pixel along
        the columns; None when absent or not positive. ``Y Converter`` is not read.

    Parameters
    ----------
    path : str or Path
        The ``.datx`` file.
    max_bytes : int, optional
        The most a dataset may make this reader allocate (default: the memory budget of
        :mod:`wavestack.pipeline.formats.limits`); a dataset must also be stored in full in the
        file (compressed by at most ``MAX_COMPRESSION_RATIO``).
    timeout_s : float
        The file is read in a child process that must finish within this time
        (:mod:`wavestack.pipeline.formats.hdf5_guard`): a damaged file can hang the HDF5 library.

    Returns
    -------
    DatxMap
        ``surface_nm`` of shape (rows, cols) in nanometres with NaN for no data.

    Raises
    ------
    InputError
        If the file is missing or not HDF5, has no surface dataset (the message names the
        paths tried), the surface is not a 2-D real array, its unit is missing or unknown,
        or an attribute read above is malformed, a dataset is larger than the memory budget or
        than the file's stored bytes justify, or the HDF5 structure is damaged (link loops,
        dangling links, unreadable chunks, a read that hangs or crashes the HDF5 library).

    References
    ----------
    .. [1] The HDF Group, *HDF5 User's Guide*; h5py documentation, "Attributes".
    .. [2] Zygo Corporation, *MetroPro Reference Guide* (OMP-0347), phase conversion.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    datx = read_guarded(functools.partial(_read_file, max_bytes=max_bytes), path, timeout_s)
    for array in (datx.surface_nm, datx.intensity):  # read-only again after the pipe
        if array is not None:
            array.flags.writeable = False
    return datx


def _read_file(path: Path, max_bytes: int | None) -> DatxMap:
    """:func:`read_datx` in the calling process."""
    try:
        h5 = h5py.File(path, "r")
    except OSError as error:
        raise InputError(f"{path}: not a readable HDF5 (.datx) file ({error})") from None
    with h5:
        try:
            return _read_open(path, h5, max_bytes)
        except InputError:
            raise
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as error:
            # h5py's own failures on a damaged or hostile structure: link loops ("too many
            # links"), dangling links, unreadable attributes or chunks
            raise InputError(f"{path}: damaged .datx (HDF5) structure: {type(error).__name__}: {error}") from None


def _read_open(path: Path, h5: h5py.File, max_bytes: int | None) -> DatxMap:
    """:func:`read_datx` on the open file."""
    surface = _data_node(h5, "Surface")
    if surface is None:
        tried = " or ".join(f"'{g}/Surface'" for g in _GROUPS)
        raise InputError(
            f"{path}: no surface data: expected a dataset {tried} "
            "(or a group holding one dataset)"
        )
    z_value = _attribute(surface, "Z Converter")
    if z_value is not None:
        _, unit, z_parameters = _converter(path, "Z Converter", z_value)
    elif (unit_value := _attribute(surface, "Unit")) is not None:
        unit, z_parameters = str(_plain(unit_value)), ()
    else:
        raise InputError(
            f"{path}: {surface.name} has neither a 'Z Converter' nor a 'Unit' attribute"
        )
    nm_per_value = _nm_per_value(path, unit, z_parameters)
    surface_nm = _masked(path, surface, "Surface", max_bytes) * nm_per_value
    surface_nm.flags.writeable = False

    lateral: float | None = None
    if (x_value := _attribute(surface, "X Converter")) is not None:
        _, _, x_parameters = _converter(path, "X Converter", x_value)
        lateral = x_parameters[1] if len(x_parameters) > 1 and x_parameters[1] > 0 else None

    intensity_node = _data_node(h5, "Intensity")
    intensity = None if intensity_node is None else _masked(path, intensity_node, "Intensity", max_bytes)
    if intensity is not None:
        intensity.flags.writeable = False
    attributes = {str(key): _plain(value) for key, value in surface.attrs.items()}
    return DatxMap(
        surface_nm=surface_nm,
        intensity=intensity,
        wavelength_nm=_wavelength_nm(path, surface, z_parameters),
        lateral_resolution_m=lateral,
        attributes=attributes,
    )
