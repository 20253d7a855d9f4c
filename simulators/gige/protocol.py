"""GVCP and GVSP seen from the camera: commands parsed, acknowledges and stream packets built.

Written from the GigE Vision 2.0 text (chapters 15, 24 and 28), separately from the driver's
parser: the two sides are tested against each other, so a shared misreading would hide.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

COMMAND_HEADER = struct.Struct(">BBHHH")  # key 0x42, flags, command, length, request id
ACK_HEADER = struct.Struct(">HHHH")  # status, acknowledge code, length, acknowledge id
GVSP_HEADER = struct.Struct(">HHI")  # status, block id, format << 24 | packet id

DISCOVERY, PACKETRESEND, READREG, WRITEREG, READMEM, WRITEMEM = 0x0002, 0x0040, 0x0080, 0x0082, 0x0084, 0x0086
SUCCESS, NOT_IMPLEMENTED, INVALID_PARAMETER, INVALID_HEADER, BAD_ALIGNMENT = 0x0000, 0x8001, 0x8002, 0x800E, 0x8005
ACCESS_DENIED = 0x8006
LEADER, TRAILER, DATA = 1, 2, 3


@dataclass(frozen=True)
class Command:
    """A command as received: flags, code, request id and payload."""

    flags: int
    code: int
    request_id: int
    payload: bytes

    @property
    def wants_ack(self) -> bool:
        return bool(self.flags & 0x01)


def parse_command(datagram: bytes) -> Command | None:
    """A command, or None for a datagram that is not one (wrong key, short, length mismatch)."""
    if len(datagram) < COMMAND_HEADER.size:
        return None
    key, flags, code, length, request_id = COMMAND_HEADER.unpack_from(datagram)
    payload = datagram[COMMAND_HEADER.size:]
    if key != 0x42 or length != len(payload):
        return None
    return Command(flags, code, request_id, bytes(payload))


def acknowledge(status: int, command: Command, payload: bytes = b"", *, ack_id: int | None = None) -> bytes:
    """The acknowledge of ``command`` (its code + 1)."""
    return ACK_HEADER.pack(status, command.code + 1, len(payload), command.request_id if ack_id is None else ack_id) \
        + payload


def discovery_payload(*, version: tuple[int, int], mac: int, ip: int, manufacturer: str, model: str,
                      device_version: str, serial: str, user_name: str) -> bytes:
    """The 248-byte DISCOVERY acknowledge payload (GigE Vision 2.0 table 15-8)."""
    def text(value: str, size: int) -> bytes:
        return value.encode("ascii", "replace")[:size].ljust(size, b"\0")
    return (struct.pack(">HHIHHI", version[0], version[1], 1 << 31, 0, mac >> 32, mac & 0xFFFF_FFFF)
            + struct.pack(">II", 0x7, 0x5) + bytes(12) + struct.pack(">I", ip) + bytes(12)
            + struct.pack(">I", 0xFF00_0000) + bytes(12) + struct.pack(">I", 0) + text(manufacturer, 32)
            + text(model, 32) + text(device_version, 32) + text("simulated device, no hardware", 48)
            + text(serial, 16) + text(user_name, 16))


def leader_packet(block_id: int, timestamp: int, pixel_format: int, width: int, height: int) -> bytes:
    """An image leader (packet id 0)."""
    return (GVSP_HEADER.pack(0, block_id, LEADER << 24)
            + struct.pack(">HHIIIIIIIHH", 0, 1, timestamp >> 32, timestamp & 0xFFFF_FFFF, pixel_format, width,
                          height, 0, 0, 0, 0))


def data_packet(block_id: int, packet_id: int, data: bytes) -> bytes:
    return GVSP_HEADER.pack(0, block_id, (DATA << 24) | packet_id) + data


def trailer_packet(block_id: int, packet_id: int, height: int) -> bytes:
    return GVSP_HEADER.pack(0, block_id, (TRAILER << 24) | packet_id) + struct.pack(">HHI", 0, 1, height)


def block_packets(block_id: int, timestamp: int, pixel_format: int, width: int, height: int, payload: bytes,
                  data_size: int) -> list[bytes]:
    """Every packet of one image block: leader, data packets of ``data_size`` bytes, trailer."""
    count = -(-len(payload) // data_size)
    return ([leader_packet(block_id, timestamp, pixel_format, width, height)]
            + [data_packet(block_id, i + 1, payload[i * data_size:(i + 1) * data_size]) for i in range(count)]
            + [trailer_packet(block_id, count + 1, height)])
