"""Register space of the simulated GigE Vision camera: bootstrap registers, the XML file, features.

Layout (big-endian, as GigE Vision registers are):

=============  ==========  ============================================================
address        length      content
=============  ==========  ============================================================
0x0000_0000    0x0A04      bootstrap registers (GigE Vision 2.0 table 28-1; the ones used)
0x0000_0D00    0x1C        stream channel 0 (SCP, SCPS, SCPD, SCDA)
0x0001_0000    0x30        the simulator's own feature registers (its XML), or a vendor's map
0x0010_0000    file size   the GenICam XML (the first URL says ``Local:NAME;100000;SIZE``)
=============  ==========  ============================================================
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Protocol

from wavestack.simulators.genicam import PERSONALITIES, read_vendor_xml
from wavestack.simulators.u3v import (FEATURES, DeviceIdentity, GenCPStatus, Register, RegisterMap, feature_register,
                                      genicam_xml, vendor_registers)

from wavestack.simulators.gige.settings import GigESimSettings

XML_ADDRESS = 0x0010_0000
XML_NAME = "wavestack_sim_gige.xml"
CCP, SCP0, SCPS0, SCPD0, SCDA0 = 0x0A00, 0x0D00, 0x0D04, 0x0D08, 0x0D18
HEARTBEAT_TIMEOUT = 0x0938
MAC = 0x02_00_5E_57_AC_01  # locally administered


class GigEHooks(Protocol):
    """What the registers ask of the camera (it implements this)."""

    def get_feature(self, name: str) -> int | float:
        ...

    def set_feature(self, name: str, value: int | float) -> GenCPStatus:
        ...

    def device_time_ns(self) -> int:
        ...


class Cells:
    """The bootstrap registers a host writes (CCP, heartbeat timeout, stream channel), by address."""

    def __init__(self, heartbeat_ms: int) -> None:
        self.values: dict[int, int] = {CCP: 0, HEARTBEAT_TIMEOUT: heartbeat_ms, SCP0: 0, SCPS0: 576, SCPD0: 0,
                                       SCDA0: 0}


def _u32(name: str, address: int, value: int) -> Register:
    data = struct.pack(">I", value)
    return Register(name, address, 4, "RO", lambda: data)


def _text(name: str, address: int, length: int, value: str) -> Register:
    data = value.encode("ascii", "replace")[:length].ljust(length, b"\0")
    return Register(name, address, length, "RO", lambda: data)


def _cell(name: str, address: int, cells: Cells, check: Callable[[int], bool] = lambda v: True) -> Register:
    def write(data: bytes) -> GenCPStatus:
        value = struct.unpack(">I", data)[0]
        if not check(value):
            return GenCPStatus.INVALID_PARAMETER
        cells.values[address] = value
        return GenCPStatus.SUCCESS
    return Register(name, address, 4, "RW", lambda: struct.pack(">I", cells.values[address]), write)


def xml_file(settings: GigESimSettings) -> bytes:
    """The GenICam file the camera serves: a vendor's XML, or its own (big-endian registers)."""
    if settings.vendor_xml is not None:
        return read_vendor_xml(settings.vendor_xml)
    identity = DeviceIdentity(settings.manufacturer, settings.model, "wavestack simulators", "1.0.0",
                              "simulated device, no hardware", settings.serial, 200, 1024, 1024)
    return genicam_xml(identity, FEATURES, (), big_endian=True, tooltip="wavestack simulated GigE Vision camera")


def build_register_map(settings: GigESimSettings, hooks: GigEHooks, cells: Cells, ip: int) -> RegisterMap:
    """The complete register space of one simulated GigE Vision camera."""
    xml = xml_file(settings)
    url = f"Local:{XML_NAME};{XML_ADDRESS:X};{len(xml):X}"
    padded = xml + bytes(-len(xml) % 4)  # READMEM moves whole words
    user_name = bytearray(16)

    def write_user(data: bytes) -> GenCPStatus:
        user_name[:] = data
        return GenCPStatus.SUCCESS

    registers = [
        _u32("Version", 0x0000, 0x0002_0000), _u32("DeviceMode", 0x0004, 0x8000_0000),
        _u32("MacHigh", 0x0008, MAC >> 32), _u32("MacLow", 0x000C, MAC & 0xFFFF_FFFF),
        _u32("NetworkInterfaceCapability", 0x0010, 0x7), _u32("NetworkInterfaceConfiguration", 0x0014, 0x5),
        _u32("CurrentIPAddress", 0x0024, ip), _u32("CurrentSubnetMask", 0x0034, 0xFF00_0000),
        _u32("CurrentDefaultGateway", 0x0044, 0),
        _text("ManufacturerName", 0x0048, 32, settings.manufacturer), _text("ModelName", 0x0068, 32, settings.model),
        _text("DeviceVersion", 0x0088, 32, "1.0.0"), _text("ManufacturerInfo", 0x00A8, 48, "simulated, no hardware"),
        _text("SerialNumber", 0x00D8, 16, settings.serial),
        Register("UserDefinedName", 0x00E8, 16, "RW", lambda: bytes(user_name), write_user),
        _text("FirstURL", 0x0200, 512, url), _text("SecondURL", 0x0400, 512, ""),
        _u32("NumberOfNetworkInterfaces", 0x0600, 1), _u32("NumberOfMessageChannels", 0x0900, 0),
        _u32("NumberOfStreamChannels", 0x0904, 1), _u32("GVCPCapability", 0x0934, 0),
        _cell("HeartbeatTimeout", HEARTBEAT_TIMEOUT, cells, lambda v: 100 <= v <= 600_000),
        _u32("TimestampTickFrequencyHigh", 0x093C, 0), _u32("TimestampTickFrequencyLow", 0x0940, 1_000_000_000),
        Register("TimestampValueHigh", 0x0948, 4, "RO", lambda: struct.pack(">I", hooks.device_time_ns() >> 32)),
        Register("TimestampValueLow", 0x094C, 4, "RO",
                 lambda: struct.pack(">I", hooks.device_time_ns() & 0xFFFF_FFFF)),
        _cell("CCP", CCP, cells, lambda v: v in (0, 1, 2, 3)),
        _cell("SCP0", SCP0, cells, lambda v: v <= 0xFFFF), _cell("SCPS0", SCPS0, cells),
        _cell("SCPD0", SCPD0, cells), _cell("SCDA0", SCDA0, cells),
        Register("GenICamFile", XML_ADDRESS, len(padded), "RO", lambda: padded),
    ]
    if settings.vendor is None:
        registers += [feature_register(spec, hooks, big_endian=True) for spec in FEATURES]  # type: ignore[arg-type]
    else:
        registers += vendor_registers(PERSONALITIES[settings.vendor], hooks)  # type: ignore[arg-type]
    return RegisterMap(registers)
