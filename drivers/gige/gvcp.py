"""GigE Vision Control Protocol (GVCP, UDP port 3956), host side, without I/O.

Every command is an 8-byte header and a payload, all big-endian: key ``0x42``, flags (bit 0:
acknowledge required), command, payload length, request id. Every acknowledge: status, answer,
payload length, acknowledge id (the request id it answers). :func:`parse_ack` checks an
acknowledge against the request it should answer; a stale or foreign acknowledge (another id) is
:class:`WrongAck`, which the channel discards while it waits.

Reference: GigE Vision 2.0, chapter 15 (GVCP): header layouts, DISCOVERY, READREG, WRITEREG,
READMEM, WRITEMEM, PACKETRESEND, PENDING_ACK; chapter 28 (bootstrap registers).
"""

from __future__ import annotations

import ipaddress
import struct
from dataclasses import dataclass

from wavestack.drivers.errors import ProtocolError

GVCP_PORT = 3956
KEY = 0x42
FLAG_ACK_REQUIRED = 0x01
FLAG_BROADCAST_ACK = 0x10  # DISCOVERY: the device may answer by broadcast

DISCOVERY_CMD, DISCOVERY_ACK = 0x0002, 0x0003
PACKETRESEND_CMD = 0x0040
READREG_CMD, READREG_ACK = 0x0080, 0x0081
WRITEREG_CMD, WRITEREG_ACK = 0x0082, 0x0083
READMEM_CMD, READMEM_ACK = 0x0084, 0x0085
WRITEMEM_CMD, WRITEMEM_ACK = 0x0086, 0x0087
PENDING_ACK = 0x0089

MAX_READMEM = 536  # bytes per READMEM/WRITEMEM so a packet fits a 576-byte datagram (GigE Vision 15.5)
MAX_REGISTERS = 67  # addresses per READREG / pairs of WRITEREG within the same bound

STATUS_NAMES = {0x0000: "SUCCESS", 0x8001: "NOT_IMPLEMENTED", 0x8002: "INVALID_PARAMETER",
                0x8003: "INVALID_ADDRESS", 0x8004: "WRITE_PROTECT", 0x8005: "BAD_ALIGNMENT",
                0x8006: "ACCESS_DENIED", 0x8007: "BUSY", 0x800B: "MSG_TIMEOUT", 0x800C: "PACKET_UNAVAILABLE",
                0x800E: "INVALID_HEADER", 0x8FFF: "ERROR"}

# bootstrap registers (GigE Vision 2.0, table 28-1)
REG_VERSION = 0x0000
REG_DEVICE_MODE = 0x0004
REG_MAC_HIGH, REG_MAC_LOW = 0x0008, 0x000C
REG_CURRENT_IP = 0x0024
REG_MANUFACTURER, REG_MODEL, REG_DEVICE_VERSION = 0x0048, 0x0068, 0x0088
REG_SERIAL, REG_USER_NAME = 0x00D8, 0x00E8
REG_FIRST_URL = 0x0200
URL_LENGTH = 512
REG_STREAM_CHANNELS = 0x0904
REG_HEARTBEAT_TIMEOUT = 0x0938
REG_TIMESTAMP_FREQ_HIGH, REG_TIMESTAMP_FREQ_LOW = 0x093C, 0x0940
REG_CCP = 0x0A00
CCP_EXCLUSIVE, CCP_CONTROL = 0x1, 0x2
REG_SCP0 = 0x0D00  # stream channel 0: host port (low 16 bits)
REG_SCPS0 = 0x0D04  # packet size (low 16 bits), bit 31 fire test packet, bit 30 do not fragment
REG_SCPD0 = 0x0D08  # inter-packet delay, timestamp ticks
REG_SCDA0 = 0x0D18  # destination IPv4 address
SCPS_DO_NOT_FRAGMENT = 0x4000_0000

_HEADER = struct.Struct(">BBHHH")
_ACK = struct.Struct(">HHHH")
_DISCOVERY = struct.Struct(">HHIHHIII12sI12sI12sI32s32s32s48s16s16s")


class WrongAck(ProtocolError):
    """An acknowledge that answers another request (another id or command): not ours, discarded."""


def status_name(status: int) -> str:
    """Name of a GEV status code (``"0x8123"`` for codes without one)."""
    return STATUS_NAMES.get(status, f"0x{status:04X}")


def encode_command(command: int, request_id: int, payload: bytes = b"", *, ack: bool = True,
                   flags: int = 0) -> bytes:
    """A GVCP command packet.

    Raises
    ------
    ValueError
        A request id outside 1..0xFFFF (0 is reserved), or a payload longer than a datagram allows.
    """
    if not 1 <= request_id <= 0xFFFF:
        raise ValueError(f"GVCP request id {request_id} outside 1..65535")
    if len(payload) > 0xFFFF or len(payload) % 4:
        raise ValueError(f"GVCP payload of {len(payload)} B; expected a multiple of 4 up to 65532")
    return _HEADER.pack(KEY, flags | (FLAG_ACK_REQUIRED if ack else 0), command, len(payload), request_id) + payload


def encode_readreg(request_id: int, addresses: list[int]) -> bytes:
    """READREG of up to :data:`MAX_REGISTERS` 4-byte-aligned addresses."""
    _check_addresses(addresses)
    return encode_command(READREG_CMD, request_id, b"".join(struct.pack(">I", a) for a in addresses))


def encode_writereg(request_id: int, pairs: list[tuple[int, int]]) -> bytes:
    """WRITEREG of up to :data:`MAX_REGISTERS` (address, u32 value) pairs."""
    _check_addresses([address for address, _ in pairs])
    if any(not 0 <= value <= 0xFFFF_FFFF for _, value in pairs):
        raise ValueError("WRITEREG values must be u32")
    return encode_command(WRITEREG_CMD, request_id, b"".join(struct.pack(">II", a, v) for a, v in pairs))


def encode_readmem(request_id: int, address: int, count: int) -> bytes:
    """READMEM of ``count`` bytes (a multiple of 4, at most :data:`MAX_READMEM`) at a 4-byte-aligned address."""
    _check_addresses([address])
    if not (0 < count <= MAX_READMEM and count % 4 == 0):
        raise ValueError(f"READMEM count {count}; expected a multiple of 4 in 4..{MAX_READMEM}")
    return encode_command(READMEM_CMD, request_id, struct.pack(">IHH", address, 0, count))


def encode_writemem(request_id: int, address: int, data: bytes) -> bytes:
    """WRITEMEM of ``data`` (a multiple of 4 bytes, at most :data:`MAX_READMEM`) at a 4-byte-aligned address."""
    _check_addresses([address])
    if not (0 < len(data) <= MAX_READMEM and len(data) % 4 == 0):
        raise ValueError(f"WRITEMEM of {len(data)} B; expected a multiple of 4 in 4..{MAX_READMEM}")
    return encode_command(WRITEMEM_CMD, request_id, struct.pack(">I", address) + data)


def encode_packetresend(request_id: int, channel: int, block_id: int, first_packet: int, last_packet: int) -> bytes:
    """PACKETRESEND (no acknowledge) of packets ``first_packet..last_packet`` of a 16-bit block id."""
    if not (0 <= block_id <= 0xFFFF and 0 <= first_packet <= last_packet <= 0xFFFFFF):
        raise ValueError(f"PACKETRESEND block {block_id} packets {first_packet}..{last_packet} out of range")
    payload = struct.pack(">HHII", channel, block_id, first_packet, last_packet)
    return encode_command(PACKETRESEND_CMD, request_id, payload, ack=False)


def _check_addresses(addresses: list[int]) -> None:
    if not 0 < len(addresses) <= MAX_REGISTERS:
        raise ValueError(f"{len(addresses)} registers in one command; expected 1..{MAX_REGISTERS}")
    if any(not 0 <= a <= 0xFFFF_FFFF or a % 4 for a in addresses):
        raise ValueError("GVCP register addresses must be 4-byte aligned u32")


@dataclass(frozen=True)
class Ack:
    """A parsed acknowledge: status, answer code, id and payload."""

    status: int
    answer: int
    ack_id: int
    payload: bytes


def parse_ack(data: bytes, device: str, *, answer: int, request_id: int) -> Ack:
    """Check an acknowledge against the request it should answer.

    A PENDING_ACK for ``request_id`` is returned as is (its payload: the ms to wait).

    Raises
    ------
    WrongAck
        An acknowledge of another request (id or answer code): discard it and keep waiting.
    ProtocolError
        Shorter than its header, or a length field that disagrees with the datagram.
    """
    if len(data) < _ACK.size:
        raise ProtocolError(device, f"GVCP acknowledge of {len(data)} B; expected at least 8")
    status, code, length, ack_id = _ACK.unpack_from(data)
    payload = bytes(data[_ACK.size:])
    if len(payload) != length:
        raise ProtocolError(device, f"GVCP acknowledge length field {length} B, datagram carries {len(payload)} B")
    if ack_id != request_id or code not in (answer, PENDING_ACK):
        raise WrongAck(device, f"GVCP acknowledge 0x{code:04X} id {ack_id}; expected 0x{answer:04X} id {request_id}")
    return Ack(status, code, ack_id, payload)


@dataclass(frozen=True)
class DeviceInfo:
    """What a DISCOVERY acknowledge says about a device."""

    address: str
    mac: str
    manufacturer: str
    model: str
    version: str
    serial: str
    user_name: str
    spec_version: tuple[int, int]


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", "replace")


def parse_discovery(payload: bytes, device: str) -> DeviceInfo:
    """The device described by a DISCOVERY acknowledge's 248-byte payload.

    Raises
    ------
    ProtocolError
        A payload of another size.
    """
    if len(payload) != _DISCOVERY.size:
        raise ProtocolError(device, f"DISCOVERY acknowledge payload of {len(payload)} B; expected {_DISCOVERY.size}")
    (major, minor, _mode, _r1, mac_high, mac_low, _options, _current, _r2, ip, _r3, _mask, _r4, _gateway,
     manufacturer, model, version, _info, serial, user) = _DISCOVERY.unpack(payload)
    mac = ((mac_high & 0xFFFF) << 32) | mac_low
    return DeviceInfo(str(ipaddress.IPv4Address(ip)), ":".join(f"{(mac >> s) & 0xFF:02x}" for s in range(40, -8, -8)),
                      _text(manufacturer), _text(model), _text(version), _text(serial), _text(user), (major, minor))


@dataclass(frozen=True)
class FileUrl:
    """Where a device keeps its GenICam file: ``Local:NAME;ADDRESS;LENGTH`` (hex) in the first URL."""

    name: str
    address: int
    length: int

    @property
    def zipped(self) -> bool:
        return self.name.lower().endswith(".zip")


def parse_first_url(raw: bytes, device: str) -> FileUrl:
    """The GenICam file location from the first-URL register (512 bytes, NUL padded).

    Raises
    ------
    ProtocolError
        Not a ``Local:`` URL (files on a vendor's web site or the host are not fetched), or bad numbers.
    """
    text = _text(raw).strip()
    if not text.lower().startswith("local:"):
        raise ProtocolError(device, f"GenICam file URL {text!r}; expected Local:NAME;ADDRESS;LENGTH in the device")
    parts = text[6:].split(";")
    if len(parts) != 3:
        raise ProtocolError(device, f"GenICam file URL {text!r}; expected Local:NAME;ADDRESS;LENGTH")
    try:
        address, length = int(parts[1], 16), int(parts[2].split("?", 1)[0], 16)
    except ValueError:
        raise ProtocolError(device, f"GenICam file URL {text!r}: address and length must be hexadecimal") from None
    if not (0 <= address <= 0xFFFF_FFFF and 0 < length <= 32 << 20):
        raise ProtocolError(device, f"GenICam file URL {text!r}: expected a u32 address and 1 B..32 MiB")
    return FileUrl(parts[0].lstrip("/"), address, length)
