"""GenCP over USB3 Vision control endpoints, host side, without I/O (sans-I/O).

Encodes READMEM/WRITEMEM command packets and parses acknowledges. Every packet starts with a
12-byte header, all fields little-endian:

======  ====  ==============================================================
offset  size  command / acknowledge field
======  ====  ==============================================================
0       4     prefix ``0x43563355`` ("U3VC" read as little-endian bytes)
4       2     flags (command; ``0x4000`` = request acknowledge) / status (ack)
6       2     command id
8       2     SCD (command-specific data) length, bytes
10      2     request id (the acknowledge echoes the command's)
======  ====  ==============================================================

References: GenICam GenCP 1.x, sections "Command and acknowledge layout"; USB3 Vision 1.0,
chapter "Device control" (the wavestack protocol sheet ``u3v_spec.md`` is the authority here).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from wavestack.drivers.errors import ProtocolError

PREFIX = 0x43563355
HEADER_SIZE = 12
FLAG_REQUEST_ACK = 0x4000

READMEM_CMD = 0x0800
READMEM_ACK = 0x0801
WRITEMEM_CMD = 0x0802
WRITEMEM_ACK = 0x0803
PENDING_ACK = 0x0805

_HEADER = struct.Struct("<IHHHH")
_READMEM_SCD = struct.Struct("<QHH")
_ADDRESS = struct.Struct("<Q")
_RESERVED_AND_U16 = struct.Struct("<HH")

_MAX_ADDRESS = 0xFFFF_FFFF_FFFF_FFFF
_MAX_U16 = 0xFFFF


class GenCPStatus(enum.IntEnum):
    """Status codes an acknowledge (or a stream trailer) may carry: GenCP, then USB3 Vision (0xA0xx)."""

    SUCCESS = 0x0000
    NOT_IMPLEMENTED = 0x8001
    INVALID_PARAMETER = 0x8002
    INVALID_ADDRESS = 0x8003
    WRITE_PROTECT = 0x8004
    BAD_ALIGNMENT = 0x8005
    ACCESS_DENIED = 0x8006
    BUSY = 0x8007
    MSG_TIMEOUT = 0x800B
    INVALID_HEADER = 0x800E
    WRONG_CONFIG = 0x800F
    GENERIC_ERROR = 0x8FFF
    RESEND_NOT_SUPPORTED = 0xA001
    DSI_ENDPOINT_HALTED = 0xA002
    SI_PAYLOAD_SIZE_NOT_ALIGNED = 0xA003
    SI_REGISTERS_INCONSISTENT = 0xA004
    DATA_DISCARDED = 0xA100
    DATA_OVERRUN = 0xA101


def status_name(status: int) -> str:
    """Readable name of a GenCP status code, e.g. ``"WRITE_PROTECT (0x8004)"``.

    Unknown codes are named by their value only (``"0x8123"``); this never raises.
    """
    try:
        return f"{GenCPStatus(status).name} (0x{status:04X})"
    except ValueError:
        return f"unknown status 0x{status:04X}"


@dataclass(frozen=True)
class Acknowledge:
    """One parsed acknowledge packet.

    Attributes
    ----------
    status
        GenCP status code (0 = success; see :class:`GenCPStatus`).
    command_id
        ``READMEM_ACK``, ``WRITEMEM_ACK``, ``PENDING_ACK`` or whatever the device sent.
    request_id
        Echo of the command's request id.
    scd
        The command-specific data, exactly ``scd_length`` bytes.
    """

    status: int
    command_id: int
    request_id: int
    scd: bytes

    @property
    def succeeded(self) -> bool:
        return self.status == GenCPStatus.SUCCESS


def next_request_id(request_id: int) -> int:
    """The request id after ``request_id``: increments, wraps at 0xFFFF and skips 0."""
    return 1 if request_id >= _MAX_U16 else request_id + 1


def _check_request_id(request_id: int) -> None:
    if not 0 <= request_id <= _MAX_U16:
        raise ValueError(f"request_id must be within 0..0xFFFF, got {request_id}")


def _check_address(address: int) -> None:
    if not 0 <= address <= _MAX_ADDRESS:
        raise ValueError(f"address must be a u64, got {address}")


def encode_readmem(request_id: int, address: int, length: int) -> bytes:
    """A READMEM_CMD packet asking for ``length`` bytes at ``address``.

    Parameters
    ----------
    request_id
        Request id, 0..0xFFFF.
    address
        Register address (u64).
    length
        Bytes to read, 1..0xFFFF (split larger reads, see :func:`max_read_chunk`).

    Returns
    -------
    bytes
        The 24-byte command packet (12-byte header + 12-byte SCD).
    """
    _check_request_id(request_id)
    _check_address(address)
    if not 1 <= length <= _MAX_U16:
        raise ValueError(f"READMEM length must be within 1..65535 bytes, got {length}")
    header = _HEADER.pack(PREFIX, FLAG_REQUEST_ACK, READMEM_CMD, _READMEM_SCD.size, request_id)
    return header + _READMEM_SCD.pack(address, 0, length)


def encode_writemem(request_id: int, address: int, data: bytes) -> bytes:
    """A WRITEMEM_CMD packet writing ``data`` at ``address``.

    Parameters
    ----------
    request_id
        Request id, 0..0xFFFF.
    address
        Register address (u64).
    data
        Bytes to write, 1..(0xFFFF - 8) (split larger writes, see :func:`max_write_chunk`).

    Returns
    -------
    bytes
        Header + SCD (8-byte address followed by the data).
    """
    _check_request_id(request_id)
    _check_address(address)
    if not 1 <= len(data) <= _MAX_U16 - _ADDRESS.size:
        raise ValueError(f"WRITEMEM data must be 1..{_MAX_U16 - _ADDRESS.size} bytes, got {len(data)}")
    scd_length = _ADDRESS.size + len(data)
    header = _HEADER.pack(PREFIX, FLAG_REQUEST_ACK, WRITEMEM_CMD, scd_length, request_id)
    return header + _ADDRESS.pack(address) + bytes(data)


def max_read_chunk(max_ack_transfer_length: int) -> int:
    """Most bytes one READMEM may ask for, given the SBRM's maximum acknowledge transfer length.

    The acknowledge carries the data after its 12-byte header; the result is rounded down to a
    multiple of 4 (register alignment) and limited to the u16 length field.

    Raises
    ------
    ValueError
        The transfer length leaves no room for 4 data bytes.
    """
    chunk = min(max_ack_transfer_length - HEADER_SIZE, _MAX_U16) // 4 * 4
    if chunk < 4:
        raise ValueError(f"maximum acknowledge transfer length {max_ack_transfer_length} B is too small")
    return chunk


def max_write_chunk(max_cmd_transfer_length: int) -> int:
    """Most data bytes one WRITEMEM may carry, given the SBRM's maximum command transfer length.

    The command carries a 12-byte header and an 8-byte address before the data; rounded down to a
    multiple of 4.

    Raises
    ------
    ValueError
        The transfer length leaves no room for 4 data bytes.
    """
    chunk = min(max_cmd_transfer_length - HEADER_SIZE - _ADDRESS.size, _MAX_U16 - _ADDRESS.size) // 4 * 4
    if chunk < 4:
        raise ValueError(f"maximum command transfer length {max_cmd_transfer_length} B is too small")
    return chunk


def ack_buffer_size(max_ack_transfer_length: int) -> int:
    """Bytes to read for one acknowledge: the SBRM's maximum acknowledge transfer length, capped at
    the largest packet GenCP can frame (12-byte header + 65535 SCD bytes).

    The SBRM field is a u32: a device announcing 4 GiB must not make the host allocate 4 GiB per read.
    """
    return max(0, min(max_ack_transfer_length, HEADER_SIZE + _MAX_U16))


def parse_acknowledge(packet: bytes, device: str) -> Acknowledge:
    """Parse one acknowledge packet read from the control IN endpoint.

    Parameters
    ----------
    packet
        The bytes of one bulk transfer.
    device
        Device name for error messages.

    Returns
    -------
    Acknowledge

    Raises
    ------
    ProtocolError
        Shorter than the header, wrong prefix, or the SCD length disagrees with the bytes received.
    """
    packet = bytes(packet)
    if len(packet) < HEADER_SIZE:
        raise ProtocolError(device, f"expected a GenCP acknowledge of >= {HEADER_SIZE} bytes, got {len(packet)}")
    prefix, status, command_id, scd_length, request_id = _HEADER.unpack_from(packet)
    if prefix != PREFIX:
        raise ProtocolError(device, f"expected acknowledge prefix 0x{PREFIX:08X}, got 0x{prefix:08X}")
    if len(packet) != HEADER_SIZE + scd_length:
        raise ProtocolError(device, f"acknowledge 0x{command_id:04X} announces {scd_length} SCD bytes, "
                                    f"got {len(packet) - HEADER_SIZE}")
    return Acknowledge(status, command_id, request_id, packet[HEADER_SIZE:])


def _reserved_and_u16(ack: Acknowledge, what: str, device: str) -> int:
    if len(ack.scd) != _RESERVED_AND_U16.size:
        raise ProtocolError(device, f"expected a {_RESERVED_AND_U16.size}-byte {what} SCD, got {len(ack.scd)} bytes")
    return _RESERVED_AND_U16.unpack(ack.scd)[1]


def pending_timeout_ms(ack: Acknowledge, device: str) -> int:
    """The temporary timeout (ms) a PENDING_ACK grants for the real acknowledge.

    Raises
    ------
    ProtocolError
        Not a PENDING_ACK, or its SCD is not 4 bytes.
    """
    if ack.command_id != PENDING_ACK:
        raise ProtocolError(device, f"expected PENDING_ACK 0x{PENDING_ACK:04X}, got 0x{ack.command_id:04X}")
    return _reserved_and_u16(ack, "PENDING_ACK", device)


def bytes_written(ack: Acknowledge, device: str) -> int:
    """Bytes the device reports written by a WRITEMEM (from a successful WRITEMEM_ACK).

    Raises
    ------
    ProtocolError
        Not a WRITEMEM_ACK, or its SCD is not 4 bytes.
    """
    if ack.command_id != WRITEMEM_ACK:
        raise ProtocolError(device, f"expected WRITEMEM_ACK 0x{WRITEMEM_ACK:04X}, got 0x{ack.command_id:04X}")
    return _reserved_and_u16(ack, "WRITEMEM_ACK", device)
