"""File formats: maps and masks (.npy/.npz/.csv), camera images, Zygo MetroPro .dat and .datx."""

from __future__ import annotations

from .datx import DatxMap, read_datx
from .images import FRAME_SUFFIXES, read_frame, read_frame_set
from .maps import InputError, load_map, load_mask
from .metropro import MetroProMap, read_metropro_dat
from .metropro_header import MetroProHeader

__all__ = [
    "DatxMap",
    "FRAME_SUFFIXES",
    "InputError",
    "MetroProHeader",
    "MetroProMap",
    "load_map",
    "load_mask",
    "read_datx",
    "read_frame",
    "read_frame_set",
    "read_metropro_dat",
]
