"""USB3 Vision image block parts (leader, trailer, payload), host side, without I/O.

A block is one leader transfer, the payload transfers and one trailer transfer. Layouts (all
little-endian, image payload type only):

Leader, 52 bytes: magic u32 ``0x4C563355`` ("U3VL"), reserved u16, leader_size u16, block_id u64,
reserved u16, payload_type u16 (1 = image), timestamp u64, pixel_format u32, size_x u32, size_y u32,
offset_x u32, offset_y u32, padding_x u16, reserved u16.

Trailer, 32 bytes: magic u32 ``0x54563355`` ("U3VT"), reserved u16, trailer_size u16, block_id u64,
status u16, reserved u16, valid_payload_size u64, size_y u32.

Reference: USB3 Vision 1.0, chapter "Streaming" (image leader and trailer); pixel format codes from
the GenICam PFNC.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.errors import ProtocolError

LEADER_MAGIC = 0x4C563355
TRAILER_MAGIC = 0x54563355
PAYLOAD_TYPE_IMAGE = 0x0001
LEADER_SIZE = 52
TRAILER_SIZE = 32

PIXEL_FORMATS: tuple[tuple[str, int, int], ...] = (
    # (name, PFNC code, bytes per pixel)
    ("Mono8", 0x01080001, 1),
    ("Mono12", 0x01100005, 2),  # 12 significant bits in a 16-bit little-endian container
    ("Mono16", 0x01100007, 2),
)

_LEADER = struct.Struct("<IHHQHHQIIIIIHH")
_TRAILER = struct.Struct("<IHHQHHQI")


def pixel_format_code(name: str) -> int:
    """PFNC code of a supported pixel format name (``"Mono8"``, ``"Mono12"``, ``"Mono16"``).

    Raises
    ------
    ValueError
        Not a supported name.
    """
    for known, code, _ in PIXEL_FORMATS:
        if known == name:
            return code
    raise ValueError(f"pixel format {name!r} is not supported; expected one of {[f[0] for f in PIXEL_FORMATS]}")


def pixel_format_name(code: int) -> str | None:
    """Name of a supported PFNC code, or ``None``."""
    for name, known, _ in PIXEL_FORMATS:
        if known == code:
            return name
    return None


def _bytes_per_pixel(code: int) -> int | None:
    for _, known, size in PIXEL_FORMATS:
        if known == code:
            return size
    return None


@dataclass(frozen=True)
class Leader:
    """An image leader.

    Attributes
    ----------
    block_id
        The device's block (frame) id.
    timestamp
        Device timestamp, ticks (ns on wavestack devices).
    pixel_format
        PFNC code.
    size_x, size_y
        Image width and height, pixels.
    offset_x, offset_y
        Region offset on the sensor, pixels.
    padding_x
        Bytes appended to each row.
    leader_size
        Size the leader announces, bytes.
    """

    block_id: int
    timestamp: int
    pixel_format: int
    size_x: int
    size_y: int
    offset_x: int
    offset_y: int
    padding_x: int
    leader_size: int

    @property
    def pixel_format_name(self) -> str | None:
        return pixel_format_name(self.pixel_format)

    def expected_payload_size(self, device: str) -> int:
        """Payload bytes this image needs: ``(size_x * bytes_per_pixel + padding_x) * size_y``.

        Raises
        ------
        ProtocolError
            Unsupported pixel format.
        """
        bpp = _bytes_per_pixel(self.pixel_format)
        if bpp is None:
            raise ProtocolError(device, f"block {self.block_id}: pixel format 0x{self.pixel_format:08X} is not "
                                        f"Mono8, Mono12 or Mono16")
        return (self.size_x * bpp + self.padding_x) * self.size_y


@dataclass(frozen=True)
class Trailer:
    """An image trailer.

    Attributes
    ----------
    block_id
        Must equal the leader's.
    status
        0 = success (a GenCP status code otherwise).
    valid_payload_size
        Payload bytes the device sent, bytes.
    size_y
        Lines actually sent.
    trailer_size
        Size the trailer announces, bytes.
    """

    block_id: int
    status: int
    valid_payload_size: int
    size_y: int
    trailer_size: int


def is_leader(transfer: bytes) -> bool:
    """Whether a transfer starts with the leader magic (cheap test used to resynchronise)."""
    return len(transfer) >= 4 and struct.unpack_from("<I", transfer)[0] == LEADER_MAGIC


def is_trailer(transfer: bytes) -> bool:
    """Whether a transfer is short enough to be a trailer and starts with the trailer magic."""
    return (TRAILER_SIZE <= len(transfer) <= 1024
            and struct.unpack_from("<I", transfer)[0] == TRAILER_MAGIC)


def parse_leader(transfer: bytes, device: str) -> Leader:
    """Parse an image leader transfer.

    Raises
    ------
    ProtocolError
        Too short, wrong magic, an announced size outside 52..len(transfer), or not an image.
    """
    transfer = bytes(transfer)
    if len(transfer) < LEADER_SIZE:
        raise ProtocolError(device, f"expected a leader of >= {LEADER_SIZE} bytes, got {len(transfer)}")
    (magic, _, leader_size, block_id, _, payload_type, timestamp, pixel_format, size_x, size_y, offset_x,
     offset_y, padding_x, _) = _LEADER.unpack_from(transfer)
    if magic != LEADER_MAGIC:
        raise ProtocolError(device, f"expected leader magic 0x{LEADER_MAGIC:08X}, got 0x{magic:08X}")
    if not LEADER_SIZE <= leader_size <= len(transfer):
        raise ProtocolError(device, f"leader announces {leader_size} bytes; expected "
                                    f"{LEADER_SIZE}..{len(transfer)}")
    if payload_type != PAYLOAD_TYPE_IMAGE:
        raise ProtocolError(device, f"block {block_id}: payload type 0x{payload_type:04X}, expected image (1)")
    return Leader(block_id, timestamp, pixel_format, size_x, size_y, offset_x, offset_y, padding_x, leader_size)


def parse_trailer(transfer: bytes, device: str) -> Trailer:
    """Parse an image trailer transfer.

    Raises
    ------
    ProtocolError
        Too short, wrong magic, or an announced size outside 32..len(transfer).
    """
    transfer = bytes(transfer)
    if len(transfer) < TRAILER_SIZE:
        raise ProtocolError(device, f"expected a trailer of >= {TRAILER_SIZE} bytes, got {len(transfer)}")
    magic, _, trailer_size, block_id, status, _, valid_payload_size, size_y = _TRAILER.unpack_from(transfer)
    if magic != TRAILER_MAGIC:
        raise ProtocolError(device, f"expected trailer magic 0x{TRAILER_MAGIC:08X}, got 0x{magic:08X}")
    if not TRAILER_SIZE <= trailer_size <= len(transfer):
        raise ProtocolError(device, f"trailer announces {trailer_size} bytes; expected "
                                    f"{TRAILER_SIZE}..{len(transfer)}")
    return Trailer(block_id, status, valid_payload_size, size_y, trailer_size)


def check_block(leader: Leader, trailer: Trailer, received: int, payload_limit: int, device: str) -> int:
    """Check that a leader, a trailer and the payload bytes received make one good image block.

    Parameters
    ----------
    leader, trailer
        Parsed leader and trailer.
    received
        Payload bytes received between them.
    payload_limit
        The payload size the stream was configured for (SIRM required payload size), bytes.
    device
        Device name for error messages.

    Returns
    -------
    int
        The valid payload size, bytes (= the image's expected size).

    Raises
    ------
    ProtocolError
        Block ids differ, the trailer reports an error status, the image needs more than the
        configured payload, or the trailer's sizes disagree with the leader or the bytes received.
    """
    block = leader.block_id
    if trailer.block_id != block:
        raise ProtocolError(device, f"trailer block id {trailer.block_id} does not match leader block id {block}")
    if trailer.status != 0:
        raise ProtocolError(device, f"block {block}: trailer status 0x{trailer.status:04X}, expected 0 (success)")
    expected = leader.expected_payload_size(device)
    if expected > payload_limit:
        raise ProtocolError(device, f"block {block}: a {leader.size_x}x{leader.size_y} image needs {expected} B, "
                                    f"more than the configured payload of {payload_limit} B")
    if trailer.valid_payload_size != expected or trailer.size_y != leader.size_y:
        raise ProtocolError(device, f"block {block}: trailer reports {trailer.valid_payload_size} B in "
                                    f"{trailer.size_y} lines, leader expects {expected} B in {leader.size_y} lines")
    if received < expected:
        raise ProtocolError(device, f"block {block}: received {received} payload bytes, expected {expected}")
    return expected


def decode_pixels(payload: bytes | bytearray | memoryview, leader: Leader, device: str) -> NDArray[np.generic]:
    """Decode an image payload into a (size_y, size_x) array.

    Mono8 gives uint8; Mono12 and Mono16 give uint16 (little-endian on the wire). Row padding
    (``padding_x`` bytes) is dropped; bytes beyond the image (transfer alignment) are ignored.

    Parameters
    ----------
    payload
        The payload bytes, at least ``leader.expected_payload_size()`` long.
    leader
        The block's leader.
    device
        Device name for error messages.

    Returns
    -------
    ndarray, shape (size_y, size_x), uint8 or uint16
        A new array owning its memory.

    Raises
    ------
    ProtocolError
        Unsupported pixel format or too few bytes.
    """
    expected = leader.expected_payload_size(device)
    if len(payload) < expected:
        raise ProtocolError(device, f"block {leader.block_id}: {len(payload)} payload bytes, expected {expected}")
    bpp = _bytes_per_pixel(leader.pixel_format) or 1
    dtype = np.dtype(np.uint8) if bpp == 1 else np.dtype("<u2")
    row_bytes = leader.size_x * bpp + leader.padding_x
    raw = np.frombuffer(payload, dtype=np.uint8, count=expected).reshape(leader.size_y, row_bytes)
    pixels = raw[:, :leader.size_x * bpp].copy().view(dtype)  # copy: C-contiguous, owns its memory
    return pixels.astype(np.uint8 if bpp == 1 else np.uint16, copy=False)
