"""The header of a Zygo MetroPro .dat file: the field table (byte offsets of header format 1, shared
by formats 2 and 3) and its parser (see :mod:`wavestack.pipeline.formats.metropro`).
"""

from __future__ import annotations

import datetime
import struct
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from .errors import InputError


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
