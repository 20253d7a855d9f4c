"""Readers for Zygo interferometer files: MetroPro ``.dat`` (binary) and Mx ``.datx`` (HDF5).

MetroPro ``.dat`` (:func:`read_metropro_dat`)
---------------------------------------------
Written from the layout in the MetroPro Reference Guide [1]_, appendix "Data File Format". A
file is a big-endian header followed by the intensity ("acquired", ``ac_``) arrays and then
the phase ("connected", ``cn_``) array:

=============  ==========  ===========  ================================================
header format  magic       header size  checked on
=============  ==========  ===========  ================================================
1              0x881B036F  834 bytes    the real file in ``/work/shared/data/zygo-dat``
2              0x881B0370  834 bytes    synthetic copies only
3              0x881B0371  4096 bytes   synthetic copies only
=============  ==========  ===========  ================================================

Formats 2 and 3 keep the fields of format 1 at the same offsets and only append fields, and
every field read here lies in the first 834 bytes, so one table (``_METROPRO_FIELDS``, byte
offsets from 0) serves all three. Each field of the table was checked against the real
format-1 file (values in the tests). The arrays:

* intensity: ``ac_n_buckets`` frames of ``ac_height`` rows x ``ac_width`` columns, unsigned
  16-bit, row-major, ``ac_n_bytes = 2 * buckets * rows * cols`` bytes; values run from 0 to
  ``ac_range``. Invalid pixels carry a marker at the top of the 16-bit range: 65535
  (``INVALID_INTENSITY``) counts as invalid, and so does any value above ``ac_range``
  (which also covers readers that put the marker threshold a little below 65535). The
  real file has no invalid intensity pixel, so this rule is unchecked on real data.
* phase: ``cn_height`` rows x ``cn_width`` columns, signed 32-bit, row-major,
  ``cn_n_bytes = 4 * rows * cols`` bytes, placed at (``cn_org_x``, ``cn_org_y``) = (col, row)
  of the camera frame; values ``>= 2147483640`` (``INVALID_PHASE``, ``invalid_phs``) are
  invalid [1]_.

Phase to length [1]_: ``waves = value * S * O / R`` and ``length = waves * wavelength_in``,
with ``S = intf_scale_factor``, ``O = obliquity_factor`` and ``R`` from ``phase_res``
(0 -> 4096, 1 -> 32768, 2 -> 131072). ``S`` is the number of waves of the measured quantity
per fringe: 0.5 for a surface measured in reflection (double pass: one fringe is half a wave
of surface height), 1 for a transmitted wavefront. The result is therefore the quantity the
instrument was set up to report, surface height when ``S = 0.5`` (as in the real file), and
the reader does not rescale it. The ``sign`` field is decoded but not applied (see
:func:`read_metropro_dat`).

Zygo Mx ``.datx`` (:func:`read_datx`)
-------------------------------------
An HDF5 file; the layout read here is documented in :func:`read_datx`. It was checked only
against synthetic files written by our own tests, never against a file from a Zygo
instrument.

References
----------
.. [1] Zygo Corporation, *MetroPro Reference Guide* (OMP-0347), appendix "Data File Format":
   header formats 1-3, field offsets and types, ``invalid_phs``, phase-resolution rule.
.. [2] The HDF Group, *HDF5 User's Guide*; h5py documentation, "Attributes" and "Compound
   types".
"""

from __future__ import annotations

import datetime
import logging
import struct
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from .maps import InputError

__all__ = [
    "INVALID_INTENSITY",
    "INVALID_PHASE",
    "METROPRO_MAGIC",
    "DatxMap",
    "MetroProHeader",
    "MetroProMap",
    "read_datx",
    "read_metropro_dat",
]

logger = logging.getLogger(__name__)

INVALID_PHASE = 2147483640  # phase values >= this are invalid ("invalid_phs")
INVALID_INTENSITY = 65535  # intensity marker of an invalid pixel
METROPRO_MAGIC = MappingProxyType({0x881B036F: 1, 0x881B0370: 2, 0x881B0371: 3})  # magic -> format
_HEADER_SIZES = MappingProxyType({1: 834, 2: 834, 3: 4096})  # header format -> header size
_PHASE_RESOLUTION = MappingProxyType({0: 4096, 1: 32768, 2: 131072})  # phase_res flag -> R
_START = struct.Struct(">IHI")  # magic_number, header_format, header_size

# name, byte offset (from 0), struct code (big-endian): the fields decoded, in file order.
_METROPRO_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("software_type", 10, "h"),
    ("software_date", 12, "30s"),
    ("software_version_major", 42, "h"),
    ("software_version_minor", 44, "h"),
    ("software_version_bug", 46, "h"),
    ("intensity_origin_col", 48, "h"),  # ac_org_x
    ("intensity_origin_row", 50, "h"),  # ac_org_y
    ("intensity_width", 52, "H"),
    ("intensity_height", 54, "H"),
    ("intensity_buckets", 56, "H"),
    ("intensity_range", 58, "H"),
    ("intensity_bytes", 60, "I"),
    ("phase_origin_col", 64, "h"),  # cn_org_x
    ("phase_origin_row", 66, "h"),  # cn_org_y
    ("phase_width", 68, "H"),
    ("phase_height", 70, "H"),
    ("phase_bytes", 72, "I"),
    ("time_stamp", 76, "i"),
    ("comment", 80, "82s"),
    ("source", 162, "h"),
    ("intf_scale_factor", 164, "f"),
    ("wavelength_in", 168, "f"),
    ("num_aperture", 172, "f"),
    ("obliquity_factor", 176, "f"),
    ("magnification", 180, "f"),
    ("camera_res", 184, "f"),
    ("acq_type", 188, "h"),
    ("phase_res", 218, "h"),
    ("sign", 232, "h"),
    ("camera_width", 234, "h"),
    ("camera_height", 236, "h"),
    ("sys_type", 238, "h"),
    ("sys_serial", 242, "H"),
    ("obj_name", 246, "12s"),
    ("part_name", 258, "40s"),
    ("phase_avg_cnt", 300, "h"),
    ("part_ser_num", 320, "40s"),
    ("refractive_index", 360, "f"),
    ("wavelength_select", 398, "8s"),
    ("pixel_width", 486, "f"),
    ("pixel_height", 490, "f"),
)


@dataclass(frozen=True)
class MetroProHeader:
    """The decoded fields of a MetroPro header (formats 1-3), in SI units where they have one.

    Float fields are stored in the file as float32; they are given here as the shortest
    decimal that round-trips in float32 (``wavelength_in`` = 6.328e-07, not 6.3279998e-07).
    Strings are cut at the first NUL and decoded as Latin-1.

    Attributes
    ----------
    magic_number : int
        0x881B036F, 0x881B0370 or 0x881B0371 (header format 1, 2, 3).
    header_format : int
        1, 2 or 3.
    header_size : int
        Bytes before the intensity data: 834 (formats 1, 2) or 4096 (format 3).
    software_type : int
        1 = MetroPro, 2 = MetroBasic, 3 = diagnostic software.
    software_date : str
        Build date of the software that wrote the file (not the measurement date).
    software_version : (int, int, int)
        Major, minor, bug-fix version.
    intensity_origin : (int, int)
        (col, row) of the intensity frame in the camera frame (``ac_org_x``, ``ac_org_y``).
    intensity_width, intensity_height : int
        Columns and rows of one intensity frame.
    intensity_buckets : int
        Number of intensity frames (0: no intensity data).
    intensity_range : int
        Largest valid intensity count (255 for an 8-bit camera).
    intensity_bytes : int
        Bytes of intensity data.
    phase_origin : (int, int)
        (col, row) of the phase array's first pixel in the camera frame.
    phase_width, phase_height : int
        Columns and rows of the phase array.
    phase_bytes : int
        Bytes of phase data.
    time_stamp : int
        Measurement time, seconds since 1970-01-01 00:00 UTC (see :attr:`measured_at`).
    comment : str
        User comment.
    source : int
        Data-source code (0 in the real file, measured on an instrument).
    intf_scale_factor : float
        ``S``, waves of the reported quantity per fringe (0.5: surface measured in reflection).
    wavelength_in : float
        Wavelength of the source, in metres.
    num_aperture : float
        Numerical aperture of the objective (0 when not set).
    obliquity_factor : float
        ``O``, obliquity factor (1 at normal incidence).
    magnification : float
        Objective magnification (0 when not set).
    camera_res : float
        Lateral resolution, metres per phase pixel at the part (0 when not calibrated).
    acq_type : int
        Acquisition type code.
    phase_res : int
        Phase-resolution flag: 0 (R = 4096), 1 (R = 32768), 2 (R = 131072).
    sign : int
        MetroPro's data-sign setting (0 = normal); decoded, not applied.
    camera_width, camera_height : int
        Size of the camera frame, in pixels.
    sys_type : int
        Instrument type code.
    sys_serial : int
        Instrument serial number.
    obj_name, part_name, part_ser_num : str
        Objective name, part name, part serial number.
    phase_avg_cnt : int
        Number of phase measurements averaged.
    refractive_index : float
        Refractive index set for the part.
    wavelength_select : str
        Which source wavelength was selected.
    pixel_width, pixel_height : float
        Camera pixel pitch, in metres.
    """

    magic_number: int
    header_format: int
    header_size: int
    software_type: int
    software_date: str
    software_version: tuple[int, int, int]
    intensity_origin: tuple[int, int]
    intensity_width: int
    intensity_height: int
    intensity_buckets: int
    intensity_range: int
    intensity_bytes: int
    phase_origin: tuple[int, int]
    phase_width: int
    phase_height: int
    phase_bytes: int
    time_stamp: int
    comment: str
    source: int
    intf_scale_factor: float
    wavelength_in: float
    num_aperture: float
    obliquity_factor: float
    magnification: float
    camera_res: float
    acq_type: int
    phase_res: int
    sign: int
    camera_width: int
    camera_height: int
    sys_type: int
    sys_serial: int
    obj_name: str
    part_name: str
    phase_avg_cnt: int
    part_ser_num: str
    refractive_index: float
    wavelength_select: str
    pixel_width: float
    pixel_height: float

    @property
    def phase_resolution(self) -> int:
        """``R``, phase counts per fringe: 4096, 32768 or 131072 (from :attr:`phase_res`)."""
        return _PHASE_RESOLUTION[self.phase_res]

    @property
    def wavelength_nm(self) -> float:
        """Source wavelength, in nanometres."""
        return self.wavelength_in * 1e9

    @property
    def lateral_resolution_m(self) -> float | None:
        """Metres per phase pixel at the part, or None when the file has no calibration."""
        return self.camera_res if self.camera_res > 0 else None

    @property
    def measured_at(self) -> datetime.datetime:
        """Measurement time (from :attr:`time_stamp`), timezone-aware UTC."""
        return datetime.datetime.fromtimestamp(self.time_stamp, tz=datetime.timezone.utc)


@dataclass(frozen=True, eq=False)
class MetroProMap:
    """A MetroPro measurement: header, phase as a length map, intensity.

    Attributes
    ----------
    header : MetroProHeader
    phase_nm : NDArray[np.float64], shape (phase_height, phase_width)
        The phase converted to length, in nanometres, NaN where invalid; row 0 is the top
        row of the phase window. Surface height when ``header.intf_scale_factor`` is 0.5,
        transmitted wavefront when 1 (see the module notes). Read-only.
    intensity : NDArray[np.uint16] or None
        Raw camera counts, shape (intensity_height, intensity_width) for one frame or
        (buckets, intensity_height, intensity_width) for several; invalid pixels keep
        their marker (see :attr:`intensity_valid`). None when the file has none. Read-only.
    valid_count : int
        Number of valid (finite) phase pixels.
    """

    header: MetroProHeader
    phase_nm: NDArray[np.float64]
    intensity: NDArray[np.uint16] | None
    valid_count: int

    @property
    def intensity_valid(self) -> NDArray[np.bool_] | None:
        """True where the intensity is a count (not 65535, not above ``intensity_range``)."""
        if self.intensity is None:
            return None
        valid = self.intensity != INVALID_INTENSITY
        if self.header.intensity_range > 0:
            valid &= self.intensity <= self.header.intensity_range
        return valid


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


# ----------------------------------------------------------------------------- MetroPro .dat


def _text(raw: bytes) -> str:
    return raw.split(b"\x00", 1)[0].decode("latin-1").strip()


def _float32(value: float) -> float:
    """The shortest decimal that round-trips in float32 (6.328e-07, not 6.3279998e-07)."""
    return float(str(np.float32(value)))


def _parse_header(path: Path, data: bytes) -> MetroProHeader:
    if len(data) < _START.size:
        raise InputError(
            f"{path}: truncated MetroPro file: {len(data)} bytes, fewer than the "
            f"{_START.size} bytes of magic number, header format and header size"
        )
    magic, header_format, header_size = _START.unpack_from(data, 0)
    if magic not in METROPRO_MAGIC:
        known = ", ".join(f"0x{m:08X} (format {f})" for m, f in METROPRO_MAGIC.items())
        raise InputError(
            f"{path}: not a MetroPro .dat file: magic number 0x{magic:08X} is none of {known}"
        )
    if header_format not in _HEADER_SIZES:
        raise InputError(
            f"{path}: MetroPro header format {header_format} is not supported (supported: 1, 2, 3)"
        )
    if header_format != METROPRO_MAGIC[magic]:
        raise InputError(
            f"{path}: inconsistent MetroPro header: magic number 0x{magic:08X} is that of header "
            f"format {METROPRO_MAGIC[magic]}, but the header format field says {header_format}"
        )
    if header_size != _HEADER_SIZES[header_format]:
        raise InputError(
            f"{path}: inconsistent MetroPro header: header format {header_format} has "
            f"{_HEADER_SIZES[header_format]} header bytes, but the header size field says "
            f"{header_size}"
        )
    if len(data) < header_size:
        raise InputError(
            f"{path}: truncated MetroPro file: {len(data)} bytes, fewer than the "
            f"{header_size}-byte header"
        )
    raw = {
        name: struct.unpack_from(">" + code, data, offset)[0]
        for name, offset, code in _METROPRO_FIELDS
    }
    values: dict[str, Any] = {}
    for name, _, code in _METROPRO_FIELDS:
        value = raw[name]
        if code.endswith("s"):
            value = _text(value)
        elif code == "f":
            value = _float32(value)
        values[name] = value
    for axis in ("intensity", "phase"):
        col, row = values.pop(f"{axis}_origin_col"), values.pop(f"{axis}_origin_row")
        values[f"{axis}_origin"] = (col, row)
    values["software_version"] = tuple(
        values.pop(f"software_version_{part}") for part in ("major", "minor", "bug")
    )
    header = MetroProHeader(
        magic_number=magic, header_format=header_format, header_size=header_size, **values
    )
    if header.phase_res not in _PHASE_RESOLUTION:
        raise InputError(
            f"{path}: MetroPro phase_res flag {header.phase_res} is not one of 0 (R = 4096), "
            f"1 (R = 32768), 2 (R = 131072)"
        )
    return header


def _check_sizes(path: Path, header: MetroProHeader, file_bytes: int) -> None:
    frame_pixels = header.intensity_width * header.intensity_height
    intensity_bytes = 2 * header.intensity_buckets * frame_pixels
    phase_bytes = 4 * header.phase_width * header.phase_height
    if header.intensity_bytes != intensity_bytes:
        raise InputError(
            f"{path}: inconsistent MetroPro header: {header.intensity_buckets} intensity "
            f"frame(s) of {header.intensity_height} x {header.intensity_width} need "
            f"{intensity_bytes} bytes, but ac_n_bytes says {header.intensity_bytes}"
        )
    if header.phase_bytes != phase_bytes:
        raise InputError(
            f"{path}: inconsistent MetroPro header: a {header.phase_height} x {header.phase_width} "
            f"phase array needs {phase_bytes} bytes, but cn_n_bytes says {header.phase_bytes}"
        )
    if phase_bytes == 0:
        raise InputError(f"{path}: the MetroPro file holds no phase data (phase array of 0 pixels)")
    needed = header.header_size + intensity_bytes + phase_bytes
    if file_bytes < needed:
        raise InputError(
            f"{path}: truncated MetroPro file: {file_bytes} bytes, but the header "
            f"({header.header_size} bytes) announces {intensity_bytes} bytes of intensity and "
            f"{phase_bytes} bytes of phase, {needed} bytes in all"
        )
    if file_bytes > needed:
        logger.debug("%s: %d bytes after the phase data ignored", path, file_bytes - needed)


def _length_per_count_nm(path: Path, header: MetroProHeader) -> float:
    scale = header.intf_scale_factor * header.obliquity_factor / header.phase_resolution
    nm_per_count = scale * header.wavelength_in * 1e9
    if not (np.isfinite(nm_per_count) and nm_per_count > 0):
        raise InputError(
            f"{path}: cannot convert MetroPro phase to length: intf_scale_factor "
            f"{header.intf_scale_factor}, obliquity_factor {header.obliquity_factor}, "
            f"wavelength_in {header.wavelength_in} m must all be positive"
        )
    return nm_per_count


def read_metropro_dat(path: str | Path) -> MetroProMap:
    """Read a Zygo MetroPro ``.dat`` file (header format 1, 2 or 3).

    Parameters
    ----------
    path : str or Path
        The ``.dat`` file.

    Returns
    -------
    MetroProMap
        ``phase_nm`` of shape (phase_height, phase_width) in nanometres with NaN for invalid
        phase (values ``>= 2147483640``), converted as ``value * S * O / R *
        wavelength_in``; ``intensity`` as raw uint16 counts of shape (rows, cols), or
        (buckets, rows, cols) when the file holds several frames, or None when it holds none.

    Raises
    ------
    InputError
        If the file is missing, its magic number is not a MetroPro one, its header format
        is not 1, 2 or 3, its header is inconsistent (format, size, byte counts, phase
        resolution flag, non-positive scale factors), or it is shorter than the header says
        its arrays need. The message names the file.

    Notes
    -----
    The ``sign`` field (MetroPro's data-sign setting) is decoded but not applied: whether
    the stored phase already carries the sign could not be checked (the real file has
    ``sign = 0``); a file with ``sign != 0`` is read as stored and a warning is logged.

    References
    ----------
    .. [1] Zygo Corporation, *MetroPro Reference Guide* (OMP-0347), appendix "Data File
       Format".
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"{path}: cannot read the file ({error})") from None
    header = _parse_header(path, data)
    _check_sizes(path, header, len(data))
    nm_per_count = _length_per_count_nm(path, header)
    if header.sign != 0:
        logger.warning(
            "%s: MetroPro sign field is %d; phase read as stored, not inverted", path, header.sign
        )

    offset = header.header_size
    intensity: NDArray[np.uint16] | None = None
    if header.intensity_bytes:
        shape = (header.intensity_buckets, header.intensity_height, header.intensity_width)
        frames = np.frombuffer(data, dtype=">u2", count=int(np.prod(shape)), offset=offset)
        intensity = frames.reshape(shape).astype(np.uint16)
        intensity = intensity[0] if header.intensity_buckets == 1 else intensity
        intensity.flags.writeable = False
        offset += header.intensity_bytes

    shape = (header.phase_height, header.phase_width)
    counts = np.frombuffer(data, dtype=">i4", count=shape[0] * shape[1], offset=offset)
    counts = counts.reshape(shape)
    valid = counts < INVALID_PHASE
    phase_nm = np.where(valid, counts.astype(np.float64) * nm_per_count, np.nan)
    phase_nm.flags.writeable = False
    valid_count = int(np.count_nonzero(valid))
    logger.debug(
        "%s: MetroPro phase %s, %d valid pixels, %.6g nm per count",
        path, shape, valid_count, nm_per_count,
    )
    return MetroProMap(
        header=header, phase_nm=phase_nm, intensity=intensity, valid_count=valid_count
    )


# ----------------------------------------------------------------------------- Zygo .datx

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


def _masked(path: Path, node: h5py.Dataset, kind: str) -> NDArray[np.float64]:
    raw = node[()]
    if raw.ndim != 2 or 0 in raw.shape or raw.dtype.kind not in "iuf":
        raise InputError(
            f"{path}: {node.name} must be a 2-D real array, "
            f"got shape {raw.shape} dtype {raw.dtype}"
        )
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
        if len(parameters) < needed or not all(p > 0 for p in parameters[1:needed]):
            raise InputError(
                f"{path}: surface in {unit} needs Z Converter Parameters (_, wavelength, S, O) "
                f"with positive values, got {parameters}"
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
        if not 1e-9 < metres < 1e-3:
            raise InputError(
                f"{path}: attribute 'Wavelength' = {metres} is not a wavelength in metres"
            )
        return metres * 1e9
    if len(z_parameters) >= 2 and 1e-9 < z_parameters[1] < 1e-3:
        return z_parameters[1] * 1e9
    return None


def read_datx(path: str | Path) -> DatxMap:
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

    Returns
    -------
    DatxMap
        ``surface_nm`` of shape (rows, cols) in nanometres with NaN for no data.

    Raises
    ------
    InputError
        If the file is missing or not HDF5, has no surface dataset (the message names the
        paths tried), the surface is not a 2-D real array, its unit is missing or unknown,
        or an attribute read above is malformed.

    References
    ----------
    .. [1] The HDF Group, *HDF5 User's Guide*; h5py documentation, "Attributes".
    .. [2] Zygo Corporation, *MetroPro Reference Guide* (OMP-0347), phase conversion.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        h5 = h5py.File(path, "r")
    except OSError as error:
        raise InputError(f"{path}: not a readable HDF5 (.datx) file ({error})") from None
    with h5:
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
        surface_nm = _masked(path, surface, "Surface") * _nm_per_value(path, unit, z_parameters)
        surface_nm.flags.writeable = False

        lateral: float | None = None
        if (x_value := _attribute(surface, "X Converter")) is not None:
            _, _, x_parameters = _converter(path, "X Converter", x_value)
            lateral = x_parameters[1] if len(x_parameters) > 1 and x_parameters[1] > 0 else None

        intensity_node = _data_node(h5, "Intensity")
        intensity = None if intensity_node is None else _masked(path, intensity_node, "Intensity")
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
