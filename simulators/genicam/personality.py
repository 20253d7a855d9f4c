"""Vendor register maps: the registers a real camera's GenApi XML describes, served by a simulator.

A :class:`VendorPersonality` is the device side of one vendor's XML: for each register the XML's
features reach (inquiry words with implemented/available bits, value, minimum, maximum, increment,
command registers), its address, length, access and what stands behind it: a constant, a stored
cell, or the camera's own state (``Width``, ``PixelFormat``, ``ExposureTime``, ...). The tables
are written from the vendor's XML as a camera's firmware would implement it, never by evaluating
the XML: the simulator does not share the driver's node map.

The camera supplies :class:`CameraHooks`; :func:`personality_registers` builds the register list.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Literal, Protocol

Access = Literal["RO", "RW", "WO"]
Codec = Literal["u32", "u64", "f64", "pixel_format", "exposure_raw"]

PFNC = MappingProxyType({"Mono8": 0x01080001, "Mono12": 0x01100005, "Mono16": 0x01100007})


class CameraHooks(Protocol):
    """What the registers ask of the camera: its state by SFNC feature name (PixelFormat as a PFNC
    code, ExposureTime in µs), and a status for every write (0 = accepted)."""

    def get_feature(self, name: str) -> int | float:
        ...

    def set_feature(self, name: str, value: int | float) -> int:
        ...


@dataclass(frozen=True)
class RegisterSpec:
    """One register of a vendor map.

    Attributes
    ----------
    address, length, access
        Where it is, how many bytes, and RO/RW/WO.
    value
        A constant (RO) or the power-on value of a stored cell (RW), when ``feature`` is None.
    feature
        The camera state behind it (read) and the feature a write sets or executes.
    codec
        How the value is stored: unsigned ``u32``/``u64``, ``f64``, the vendor's ``pixel_format``
        code, or ``exposure_raw`` (an integer count of :attr:`VendorPersonality.exposure_unit_us`).
    command_value
        What a command register takes to execute (the XML's ``CommandValue``).
    """

    address: int
    length: int = 4
    access: Access = "RO"
    value: int | float = 0
    feature: str | None = None
    codec: Codec = "u32"
    command_value: int = 1


@dataclass(frozen=True)
class VendorPersonality:
    """The device side of one vendor's GenApi XML.

    Attributes
    ----------
    name
        Short name (``"flir-bfs"``, ``"alvium-1800u"``, ``"basler-ace-gige"``).
    transport
        The interface the XML was written for (``"u3v"`` or ``"gige"``).
    endianness
        Byte order of the registers (the XML's ``Endianess``).
    registers
        Every register the XML's station features reach.
    pixel_formats
        Pixel format name -> the code the device stores (PFNC, or the vendor's own).
    exposure_unit_us
        The unit of an ``exposure_raw`` register, µs.
    """

    name: str
    transport: Literal["u3v", "gige"]
    endianness: Literal["little", "big"]
    registers: tuple[RegisterSpec, ...]
    pixel_formats: Mapping[str, int] = field(default_factory=dict)
    exposure_unit_us: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "pixel_formats", MappingProxyType(dict(self.pixel_formats)))


def read_vendor_xml(path: str | Path) -> bytes:
    """A vendor XML as a camera's manifest serves it: from its ``<?xml`` declaration (or first tag) on.

    Capture tools sometimes write a line before the declaration (a device id); the camera does not.
    """
    data = Path(path).read_bytes()
    start = data.find(b"<?xml")
    return data[start if start >= 0 else max(data.find(b"<"), 0):]


_COMMANDS = frozenset({"AcquisitionStart", "AcquisitionStop", "TriggerSoftware"})
MIN_SIDE, MAX_SIDE = 16, 16384


def _acceptable(name: str, value: int | float, command_value: int) -> bool:
    """The camera's own range checks (the XML's limits say the same to the host)."""
    if name in ("Width", "Height"):
        return MIN_SIDE <= value <= MAX_SIDE
    if name == "TriggerMode":
        return value in (0, 1)
    if name in _COMMANDS:
        return value == command_value
    if name == "AcquisitionMode":
        return 0 <= value <= 2
    return value == value  # ExposureTime: finite, checked after conversion


class _Cell:
    def __init__(self, value: int | float) -> None:
        self.value = value


def _packer(spec: RegisterSpec, order: str) -> Callable[[int | float], bytes]:
    if spec.codec == "f64":
        return lambda value: struct.pack(order + "d", float(value))
    return lambda value: (int(value) & ((1 << (8 * spec.length)) - 1)).to_bytes(
        spec.length, "big" if order == ">" else "little")


def _unpacker(spec: RegisterSpec, order: str) -> Callable[[bytes], int | float]:
    if spec.codec == "f64":
        return lambda data: struct.unpack(order + "d", data)[0]
    return lambda data: int.from_bytes(data, "big" if order == ">" else "little")


def register_accessors(personality: VendorPersonality, spec: RegisterSpec, hooks: CameraHooks,
                       invalid: int) -> tuple[Callable[[], bytes], Callable[[bytes], int] | None]:
    """``read()`` and ``write(data) -> status`` of one register (``invalid``: the transport's
    status for a value the camera refuses)."""
    order = ">" if personality.endianness == "big" else "<"
    pack, unpack = _packer(spec, order), _unpacker(spec, order)
    codes = dict(personality.pixel_formats)
    if spec.feature is None:
        cell = _Cell(spec.value)

        def write_cell(data: bytes) -> int:
            cell.value = unpack(data)
            return 0

        return (lambda: pack(cell.value)), (write_cell if spec.access != "RO" else None)
    name = spec.feature

    def read() -> bytes:
        if spec.access == "WO":
            return bytes(spec.length)
        value = hooks.get_feature(name)
        if spec.codec == "pixel_format":
            value = next((codes[n] for n, code in PFNC.items() if code == value and n in codes), 0)
        elif spec.codec == "exposure_raw":
            value = round(float(value) / personality.exposure_unit_us)
        return pack(value)

    def write(data: bytes) -> int:
        value = unpack(data)
        if not _acceptable(name, value, spec.command_value):
            return invalid
        if spec.codec == "pixel_format":
            names = [n for n, code in codes.items() if code == value and n in PFNC]
            if not names:
                return invalid
            value = PFNC[names[0]]
        elif spec.codec == "exposure_raw":
            value = float(value) * personality.exposure_unit_us
        if name == "ExposureTime" and not 1.0 <= value <= 30e6:
            return invalid
        return hooks.set_feature(name, value)

    return read, (write if spec.access != "RO" else None)
