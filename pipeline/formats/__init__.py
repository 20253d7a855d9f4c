"""File formats: maps and masks (.npy), camera images, measured maps (Zygo MetroPro .dat and .datx,
4D Technology 4Sight .h5), and what is not supported."""

from __future__ import annotations

from .datx import DatxMap, read_datx
from .errors import InputError
from .fourd import FourDMap, read_4d
from .hdf5_open import OpenedHDF5, open_hdf5_readonly
from .images import FRAME_SUFFIXES, read_frame, read_frame_set
from .limits import check_allocation
from .maps import load_map, load_mask
from .measured import (
    MEASURED_MAP_SUFFIXES,
    SUPPORTED_FILES,
    MeasuredMap,
    read_measured_map,
    unsupported_reason,
)
from .metropro import MetroProMap, read_metropro_dat
from .metropro_header import MetroProHeader

__all__ = [
    "DatxMap",
    "FRAME_SUFFIXES",
    "FourDMap",
    "InputError",
    "MEASURED_MAP_SUFFIXES",
    "MeasuredMap",
    "MetroProHeader",
    "MetroProMap",
    "OpenedHDF5",
    "SUPPORTED_FILES",
    "check_allocation",
    "load_map",
    "load_mask",
    "open_hdf5_readonly",
    "read_4d",
    "read_datx",
    "read_frame",
    "read_frame_set",
    "read_measured_map",
    "read_metropro_dat",
    "unsupported_reason",
]
