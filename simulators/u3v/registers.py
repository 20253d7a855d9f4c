"""Register space of the simulated USB3 Vision camera: bootstrap registers, manifest, XML, features.

Layout (addresses are the simulator's choice where the protocol sheet leaves them open):

=============  ==========  ===========================================================
address        length      content
=============  ==========  ===========================================================
0x0000_0000    0x210       ABRM (GenCP technology-agnostic bootstrap, sheet table)
0x0000_1000    0x44        SBRM (USB3 Vision bootstrap)
0x0000_2000    0x30        SIRM (streaming interface)
0x0000_3000    8 + 64      manifest table (one entry)
0x0001_0000    0x30        feature registers (see :data:`FEATURES`)
0x0010_0000    file size   the GenICam XML file (plain or ZIP, per the manifest entry)
=============  ==========  ===========================================================

Access rules (GenCP status codes): a read or write touching an unmapped byte -> INVALID_ADDRESS; a
read of a write-only register -> ACCESS_DENIED; a write touching a read-only register -> WRITE_PROTECT
(checked first); a write that covers only part of a register -> BAD_ALIGNMENT; a value outside a feature's range or
enumeration -> INVALID_PARAMETER. A read may cover several adjacent registers or part of one (the
host reads the XML file in chunks). The ABRM timestamp latch reads as 0 so that a host can read the
whole ABRM in one command.

The address-space machinery is in :mod:`.register_map`, the identity and feature table in
:mod:`.device_description`, the XML and manifest file in :mod:`.genicam_xml`; their names are
re-exported here. This module builds the camera's register space from them.
"""

from __future__ import annotations

import hashlib
import math
import struct
from collections.abc import Callable
from typing import Protocol

from wavestack.simulators.genicam import VendorPersonality, register_accessors
from wavestack.simulators.u3v.device_description import (ABRM_ADDRESS, DEVICE_STRINGS, FEATURE_BASE_ADDRESS, FEATURES,
                                                         PIXEL_FORMAT_ENTRIES, DeviceIdentity, FeatureKind,
                                                         FeatureSpec)
from wavestack.simulators.u3v.genicam_xml import (FILE_TYPE_XML, FILE_TYPE_ZIP, GENICAM_NAMESPACE, XML_FILE_NAME,
                                                  genicam_xml, manifest_file)
from wavestack.simulators.u3v.register_map import AccessMode, GenCPStatus, Register, RegisterMap

__all__ = [
    "ABRM_ADDRESS", "FEATURE_BASE_ADDRESS", "FEATURES", "FILE_TYPE_XML", "FILE_TYPE_ZIP", "GENICAM_NAMESPACE",
    "MANIFEST_ADDRESS", "PIXEL_FORMAT_ENTRIES", "SBRM_ADDRESS", "SIRM_ADDRESS", "SIRM_FIELDS", "SIRM_LENGTH",
    "XML_ADDRESS", "XML_FILE_NAME", "AccessMode", "DeviceIdentity", "FeatureKind", "FeatureSpec", "GenCPStatus",
    "Register", "RegisterHooks", "RegisterMap", "build_register_map", "feature_register", "genicam_xml", "vendor_registers", "manifest_file",
]

SBRM_ADDRESS = 0x0000_1000
SIRM_ADDRESS = 0x0000_2000
SIRM_LENGTH = 0x30
MANIFEST_ADDRESS = 0x0000_3000
XML_ADDRESS = 0x0010_0000


class RegisterHooks(Protocol):
    """What the register space asks of the device it belongs to (the camera implements it)."""

    def device_time_ns(self) -> int:
        """Device clock in ns (1 tick = 1 ns)."""
        ...

    def get_feature(self, name: str) -> int | float:
        """Current value of a readable feature of :data:`FEATURES`."""
        ...

    def set_feature(self, name: str, value: int | float) -> GenCPStatus:
        """Apply an already range-checked feature value, or execute a command."""
        ...

    def get_stream_register(self, offset: int) -> int:
        """SIRM field at ``offset``."""
        ...

    def set_stream_register(self, offset: int, value: int) -> GenCPStatus:
        """Write the SIRM field at ``offset``."""
        ...


def _constant(name: str, address: int, data: bytes) -> Register:
    return Register(name, address, len(data), "RO", lambda: data)


def _text(name: str, address: int, value: str, length: int = 64) -> Register:
    raw = value.encode("ascii", "replace")[:length]
    return _constant(name, address, raw.ljust(length, b"\0"))


class _StoredBytes:
    """A plain read/write memory cell (device configuration, user-defined name...)."""

    def __init__(self, length: int) -> None:
        self._data = bytes(length)

    def read(self) -> bytes:
        return self._data

    def write(self, data: bytes) -> GenCPStatus:
        self._data = bytes(data)
        return GenCPStatus.SUCCESS


class _TimestampLatch:
    """ABRM timestamp: writing 1 to the latch copies the device clock into the timestamp register."""

    def __init__(self, clock: Callable[[], int]) -> None:
        self._clock = clock
        self._latched = 0

    def read_timestamp(self) -> bytes:
        return struct.pack("<Q", self._latched)

    def write_latch(self, data: bytes) -> GenCPStatus:
        if struct.unpack("<I", data)[0] != 1:
            return GenCPStatus.INVALID_PARAMETER
        self._latched = self._clock() & 0xFFFF_FFFF_FFFF_FFFF
        return GenCPStatus.SUCCESS


def _abrm(identity: DeviceIdentity, hooks: RegisterHooks) -> list[Register]:
    a = ABRM_ADDRESS
    latch = _TimestampLatch(hooks.device_time_ns)
    user_name, device_config = _StoredBytes(64), _StoredBytes(8)
    # capability bits (informational, the sheet does not define them): user-defined name, timestamp,
    # family name, SBRM present, WRITEMEM_ACK carries the written length
    capability = (1 << 0) | (1 << 3) | (1 << 8) | (1 << 9) | (1 << 11)
    # the strings are also the Device Control features of the XML (DEVICE_STRINGS says where)
    text = {"ManufacturerName": identity.manufacturer, "ModelName": identity.model, "FamilyName": identity.family,
            "DeviceVersion": identity.device_version, "ManufacturerInfo": identity.manufacturer_info,
            "SerialNumber": identity.serial}
    strings = [_text(spec.abrm_register, spec.address, text[spec.abrm_register], spec.length)
               if spec.access == "RO" else
               Register(spec.abrm_register, spec.address, spec.length, spec.access, user_name.read, user_name.write)
               for spec in DEVICE_STRINGS]
    return [
        _constant("GenCPVersion", a + 0x0000, struct.pack("<HH", 0, 1)),
        *strings,
        _constant("DeviceCapability", a + 0x01C4, struct.pack("<Q", capability)),
        _constant("MaximumDeviceResponseTime", a + 0x01CC, struct.pack("<I", identity.max_response_time_ms)),
        _constant("ManifestTableAddress", a + 0x01D0, struct.pack("<Q", MANIFEST_ADDRESS)),
        _constant("SBRMAddress", a + 0x01D8, struct.pack("<Q", SBRM_ADDRESS)),
        Register("DeviceConfiguration", a + 0x01E0, 8, "RW", device_config.read, device_config.write),
        _constant("ReservedHeartbeatAndMessageChannel", a + 0x01E8, bytes(8)),
        Register("Timestamp", a + 0x01F0, 8, "RO", latch.read_timestamp),
        Register("TimestampLatch", a + 0x01F8, 4, "RW", lambda: bytes(4), latch.write_latch),
        _constant("TimestampIncrement", a + 0x01FC, struct.pack("<Q", 1)),
        _constant("ReservedAccessAndEndianness", a + 0x0204, bytes(12)),
    ]


def _sbrm(identity: DeviceIdentity) -> list[Register]:
    s = SBRM_ADDRESS
    u3vcp_config = _StoredBytes(8)
    return [
        _constant("U3VVersion", s + 0x00, struct.pack("<HH", 0, 1)),
        _constant("U3VCPCapability", s + 0x04, struct.pack("<Q", 1)),  # bit 0: SIRM available
        Register("U3VCPConfiguration", s + 0x0C, 8, "RW", u3vcp_config.read, u3vcp_config.write),
        _constant("MaximumCommandTransferLength", s + 0x14, struct.pack("<I", identity.max_command_bytes)),
        _constant("MaximumAcknowledgeTransferLength", s + 0x18, struct.pack("<I", identity.max_ack_bytes)),
        _constant("NumberOfStreamChannels", s + 0x1C, struct.pack("<I", 1)),
        _constant("SIRMAddress", s + 0x20, struct.pack("<Q", SIRM_ADDRESS)),
        _constant("SIRMLength", s + 0x28, struct.pack("<I", SIRM_LENGTH)),
        _constant("EIRMAddress", s + 0x2C, struct.pack("<Q", 0)),
        _constant("EIRMLength", s + 0x34, struct.pack("<I", 0)),
        _constant("IIDC2Address", s + 0x38, struct.pack("<Q", 0)),
        _constant("CurrentSpeed", s + 0x40, struct.pack("<I", 0x8)),  # bit 3: SuperSpeed
    ]


#: SIRM fields: (offset, length, access, name)
SIRM_FIELDS: tuple[tuple[int, int, AccessMode, str], ...] = (
    (0x00, 4, "RO", "SIInfo"), (0x04, 4, "RW", "SIControl"), (0x08, 8, "RO", "SIRequiredPayloadSize"),
    (0x10, 4, "RO", "SIRequiredLeaderSize"), (0x14, 4, "RO", "SIRequiredTrailerSize"),
    (0x18, 4, "RW", "SIMaximumLeaderSize"), (0x1C, 4, "RW", "SIPayloadTransferSize"),
    (0x20, 4, "RW", "SIPayloadTransferCount"), (0x24, 4, "RW", "SIPayloadFinalTransfer1Size"),
    (0x28, 4, "RW", "SIPayloadFinalTransfer2Size"), (0x2C, 4, "RW", "SIMaximumTrailerSize"),
)


def _unsigned(name: str, address: int, length: int, access: AccessMode, get: Callable[[], int],
              put: Callable[[int], GenCPStatus] | None) -> Register:
    fmt = "<I" if length == 4 else "<Q"
    write = None if put is None else (lambda data: put(struct.unpack(fmt, data)[0]))
    return Register(name, address, length, access, lambda: struct.pack(fmt, get()), write)


def _sirm(hooks: RegisterHooks) -> list[Register]:
    registers = []
    for offset, length, access, name in SIRM_FIELDS:
        put = None if access == "RO" else (lambda v, o=offset: hooks.set_stream_register(o, v))
        registers.append(_unsigned(name, SIRM_ADDRESS + offset, length, access,
                                   lambda o=offset: hooks.get_stream_register(o), put))
    return registers


def feature_register(spec: FeatureSpec, hooks: RegisterHooks, *, big_endian: bool = False) -> Register:
    """The register behind one feature of :data:`FEATURES` (range-checked writes, the camera's state on reads)."""
    order = ">" if big_endian else "<"
    def write(data: bytes) -> GenCPStatus:
        if spec.kind == "Float":
            value: float | int = struct.unpack(order + "d", data)[0]
            if not math.isfinite(value):
                return GenCPStatus.INVALID_PARAMETER
        else:
            value = int.from_bytes(data, "big" if big_endian else "little")
        if spec.kind == "Command" and value != spec.command_value:
            return GenCPStatus.INVALID_PARAMETER
        if spec.kind == "Enumeration" and value not in {v for _, v in spec.entries}:
            return GenCPStatus.INVALID_PARAMETER
        if (spec.minimum is not None and value < spec.minimum) or (spec.maximum is not None and value > spec.maximum):
            return GenCPStatus.INVALID_PARAMETER
        return hooks.set_feature(spec.name, value)

    def read() -> bytes:
        value = hooks.get_feature(spec.name)
        if spec.kind == "Float":
            return struct.pack(order + "d", float(value))
        return int(value).to_bytes(spec.length, "big" if big_endian else "little")

    return Register(spec.name + "Reg", spec.address, spec.length, spec.access, read, write)


def _manifest(file: bytes, format_info: int) -> list[Register]:
    version = (1 << 24) | (0 << 16) | 0  # file version 1.0.0
    entry = struct.pack("<IIQQ", version, format_info, XML_ADDRESS, len(file)) + hashlib.sha1(file).digest()
    entry = entry.ljust(64, b"\0")
    return [_constant("ManifestEntryCount", MANIFEST_ADDRESS, struct.pack("<Q", 1)),
            _constant("ManifestEntry0", MANIFEST_ADDRESS + 8, entry),
            _constant("GenICamFile", XML_ADDRESS, file)]


def vendor_registers(personality: VendorPersonality, hooks: RegisterHooks) -> list[Register]:
    """The registers of a real camera's map, on this camera's state."""
    registers = []
    for spec in personality.registers:
        read, write = register_accessors(personality, spec, hooks, GenCPStatus.INVALID_PARAMETER)
        registers.append(Register(f"{personality.name}@0x{spec.address:X}", spec.address, spec.length, spec.access,
                                  read, None if write is None else (lambda data, w=write: GenCPStatus(w(data)))))
    return registers


def build_register_map(identity: DeviceIdentity, hooks: RegisterHooks, *, zipped_xml: bool,
                       vendor: tuple[VendorPersonality, bytes] | None = None) -> RegisterMap:
    """The complete register space of one simulated camera.

    Parameters
    ----------
    identity
        Strings and limits reported by the bootstrap registers.
    hooks
        The device behind the SIRM and feature registers.
    zipped_xml
        Serve the GenICam file as a ZIP archive instead of plain XML.
    vendor
        A real camera's register map and its XML, served instead of the simulator's own.
    """
    xml = genicam_xml(identity) if vendor is None else vendor[1]
    file, format_info = manifest_file(xml, zipped_xml)
    registers = _abrm(identity, hooks) + _sbrm(identity) + _sirm(hooks) + _manifest(file, format_info)
    if vendor is None:
        registers += [feature_register(spec, hooks) for spec in FEATURES]
    else:
        registers += vendor_registers(vendor[0], hooks)
    return RegisterMap(registers)
