"""GigE Vision Streaming Protocol (GVSP), host side, without I/O: packets into whole images.

A block (one image) travels as a leader packet (id 0), data packets (ids 1..n) and a trailer
(id n + 1), each a UDP datagram with an 8-byte header, big-endian: status u16, block id u16,
packet format u8 (1 leader, 2 trailer, 3 data), packet id u24. The image leader carries payload
type 1, a 64-bit timestamp, the PFNC pixel format, width, height, offsets and padding.

:class:`BlockAssembler` puts packets into place by id, whatever order they arrive in, asks for
the missing ones (:attr:`Progress.resend`, for PACKETRESEND) as soon as the trailer has come, or when
the block has waited :attr:`BlockAssembler.resend_after_s` (also between rounds), gives a block up after
:attr:`BlockAssembler.give_up_after_s` or as many resend rounds, and hands on only complete blocks:
an image is never assembled from a block with a hole in it.

Reference: GigE Vision 2.0, chapter 24 (GVSP): header, image leader and trailer, packet resend.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.errors import ProtocolError

FORMAT_LEADER, FORMAT_TRAILER, FORMAT_DATA = 1, 2, 3
PAYLOAD_IMAGE = 0x0001
HEADER_SIZE = 8
LEADER_SIZE = HEADER_SIZE + 36
TRAILER_SIZE = HEADER_SIZE + 8
MAX_PACKET = 9000 - 28  # a jumbo frame's datagram (a GVSP packet never exceeds the negotiated size)
BYTES_PER_PIXEL = {0x01080001: 1, 0x01100005: 2, 0x01100007: 2}  # Mono8, Mono12 (unpacked), Mono16
PIXEL_FORMAT_NAMES = {0x01080001: "Mono8", 0x01100005: "Mono12", 0x01100007: "Mono16"}

_HEADER = struct.Struct(">HHI")
_LEADER = struct.Struct(">HHIIIIIIIHH")
_TRAILER = struct.Struct(">HHI")


@dataclass(frozen=True)
class Packet:
    """One GVSP packet's header and what follows it."""

    status: int
    block_id: int
    packet_format: int
    packet_id: int
    body: bytes


def parse_packet(data: bytes, device: str) -> Packet:
    """Split a datagram into header and body.

    Raises
    ------
    ProtocolError
        Shorter than the header, longer than :data:`MAX_PACKET`, an extended-id packet (not
        negotiated: the host leaves extended ids off) or an unknown packet format.
    """
    if len(data) < HEADER_SIZE or len(data) > MAX_PACKET:
        raise ProtocolError(device, f"GVSP packet of {len(data)} B; expected {HEADER_SIZE}..{MAX_PACKET}")
    status, block_id, word = _HEADER.unpack_from(data)
    packet_format = (word >> 24) & 0x7F
    if word >> 31:
        raise ProtocolError(device, "GVSP packet with extended ids; expected the standard 16-bit block id")
    if packet_format not in (FORMAT_LEADER, FORMAT_TRAILER, FORMAT_DATA):
        raise ProtocolError(device, f"GVSP packet format {packet_format}; expected 1, 2 or 3")
    return Packet(status, block_id, packet_format, word & 0xFF_FFFF, bytes(data[HEADER_SIZE:]))


@dataclass(frozen=True)
class ImageLeader:
    """The leader of an image block."""

    timestamp: int
    pixel_format: int
    width: int
    height: int
    padding_x: int

    def payload_size(self) -> int:
        bpp = BYTES_PER_PIXEL[self.pixel_format]
        return (self.width * bpp + self.padding_x) * self.height


def parse_leader(body: bytes, device: str, max_payload: int) -> ImageLeader:
    """An image leader's fields, checked against what the host can take.

    Raises
    ------
    ProtocolError
        Not an image leader, an unsupported pixel format, or a payload over ``max_payload`` bytes.
    """
    if len(body) < _LEADER.size:
        raise ProtocolError(device, f"GVSP leader of {len(body)} B; expected {_LEADER.size}")
    (_reserved, payload_type, ts_high, ts_low, pixel_format, width, height, _ox, _oy, padding_x,
     _padding_y) = _LEADER.unpack_from(body)
    if payload_type != PAYLOAD_IMAGE:
        raise ProtocolError(device, f"GVSP payload type 0x{payload_type:04X}; expected an image (1)")
    if pixel_format not in BYTES_PER_PIXEL:
        raise ProtocolError(device, f"pixel format 0x{pixel_format:08X}; expected Mono8, Mono12 or Mono16")
    leader = ImageLeader((ts_high << 32) | ts_low, pixel_format, width, height, padding_x)
    if not (0 < width <= 65535 and 0 < height <= 65535) or leader.payload_size() > max_payload:
        raise ProtocolError(device, f"a {width} x {height} image does not fit the configured {max_payload} B")
    return leader


@dataclass(frozen=True)
class Image:
    """An assembled image block: block id, leader, pixels (height, width)."""

    block_id: int
    leader: ImageLeader
    pixels: NDArray[np.generic]


@dataclass
class Progress:
    """What one call to the assembler produced."""

    images: list[Image] = field(default_factory=list)
    dropped: list[tuple[int, str]] = field(default_factory=list)  # (block id, why)
    resend: list[tuple[int, int, int]] = field(default_factory=list)  # (block id, first, last packet)


@dataclass
class _Block:
    leader: ImageLeader | None
    started: float
    last_seen: float
    chunks: dict[int, bytes] = field(default_factory=dict)
    last_packet: int | None = None  # the trailer's packet id, once known
    resend_rounds: int = 0
    asked_at: float = -1.0


class BlockAssembler:
    """Packets (any order, resent or not) into complete images; pure, the caller passes the clock.

    Parameters
    ----------
    device
        Name for messages.
    data_size
        Payload bytes per data packet (the negotiated packet size less IP, UDP and GVSP headers).
    max_payload
        The largest image payload the host accepts, bytes.
    resend_after_s, give_up_after_s, max_resend_rounds
        When missing packets are asked for again, and when a block is given up.
    """

    def __init__(self, device: str, data_size: int, max_payload: int, *, resend_after_s: float = 0.05,
                 give_up_after_s: float = 0.5, max_resend_rounds: int = 3, max_blocks: int = 4) -> None:
        self._device = device
        self._data_size = data_size
        self._max_payload = max_payload
        self.resend_after_s = resend_after_s
        self.give_up_after_s = give_up_after_s
        self._rounds = max_resend_rounds
        self._max_blocks = max_blocks
        self._blocks: dict[int, _Block] = {}
        self._finished: dict[int, None] = {}  # recently completed or dropped ids (resent duplicates ignored)

    def _expected_packets(self, leader: ImageLeader) -> int:
        return -(-leader.payload_size() // self._data_size)

    def feed(self, packet: Packet, now: float) -> Progress:
        """Take one packet; returns what completed, what was dropped and what to ask for again."""
        progress = Progress()
        if packet.block_id in self._finished:
            return progress
        block = self._blocks.get(packet.block_id)
        if block is None:
            if len(self._blocks) >= self._max_blocks:  # the oldest unfinished block cannot complete in time
                oldest = min(self._blocks, key=lambda b: self._blocks[b].started)
                self._drop(oldest, "overtaken by newer blocks", progress)
            block = self._blocks[packet.block_id] = _Block(None, now, now)
        block.last_seen = now
        try:
            self._place(packet, block)
        except ProtocolError as error:
            self._drop(packet.block_id, error.detail, progress)
            return progress
        if packet.packet_format == FORMAT_TRAILER:
            self._ask(packet.block_id, block, now, progress)
        self._complete(packet.block_id, block, progress)
        return progress

    def _place(self, packet: Packet, block: _Block) -> None:
        if packet.status != 0:
            raise ProtocolError(self._device, f"block {packet.block_id}: packet status 0x{packet.status:04X}")
        if packet.packet_format == FORMAT_LEADER:
            if packet.packet_id != 0:
                raise ProtocolError(self._device, f"block {packet.block_id}: leader with packet id {packet.packet_id}")
            block.leader = parse_leader(packet.body, self._device, self._max_payload)
        elif packet.packet_format == FORMAT_TRAILER:
            block.last_packet = packet.packet_id
        else:
            if len(packet.body) > self._data_size or packet.packet_id == 0:
                raise ProtocolError(self._device, f"block {packet.block_id}: data packet {packet.packet_id} of "
                                                  f"{len(packet.body)} B; expected at most {self._data_size} B")
            if block.leader is not None and packet.packet_id > self._expected_packets(block.leader):
                raise ProtocolError(self._device, f"block {packet.block_id}: data packet {packet.packet_id} beyond "
                                                  f"the image's {self._expected_packets(block.leader)}")
            block.chunks[packet.packet_id] = packet.body

    def _missing(self, block: _Block) -> list[tuple[int, int]]:
        last = block.last_packet if block.last_packet is not None else (
            self._expected_packets(block.leader) + 1 if block.leader is not None else None)
        if last is None:
            return []
        wanted = ([0] if block.leader is None else []) + [i for i in range(1, last) if i not in block.chunks]
        if block.last_packet is None:
            wanted.append(last)
        ranges: list[tuple[int, int]] = []
        for i in wanted:
            if ranges and ranges[-1][1] == i - 1:
                ranges[-1] = (ranges[-1][0], i)
            else:
                ranges.append((i, i))
        return ranges

    def _ask(self, block_id: int, block: _Block, now: float, progress: Progress) -> None:
        missing = self._missing(block)
        if not missing or now - block.asked_at < self.resend_after_s:
            return
        if block.resend_rounds >= self._rounds:
            return
        block.resend_rounds += 1
        block.asked_at = now
        progress.resend.extend((block_id, first, last) for first, last in missing)

    def _complete(self, block_id: int, block: _Block, progress: Progress) -> None:
        leader = block.leader
        if leader is None or block.last_packet is None:
            return
        expected = self._expected_packets(leader)
        if block.last_packet != expected + 1:
            self._drop(block_id, f"trailer at packet {block.last_packet}, the image needs {expected} data packets",
                       progress)
            return
        if len(block.chunks) < expected:
            return
        payload = b"".join(block.chunks[i] for i in range(1, expected + 1))
        if len(payload) != leader.payload_size():
            self._drop(block_id, f"{len(payload)} B of data for a {leader.payload_size()}-byte image", progress)
            return
        dtype = np.uint8 if BYTES_PER_PIXEL[leader.pixel_format] == 1 else np.dtype("<u2")
        row = leader.width * BYTES_PER_PIXEL[leader.pixel_format] + leader.padding_x
        rows = np.frombuffer(payload, np.uint8).reshape(leader.height, row)[:, :row - leader.padding_x]
        pixels = np.ascontiguousarray(rows).view(dtype).reshape(leader.height, leader.width)
        progress.images.append(Image(block_id, leader, pixels.astype(np.uint16 if dtype != np.uint8 else np.uint8)))
        self._finish(block_id)

    def _drop(self, block_id: int, reason: str, progress: Progress) -> None:
        progress.dropped.append((block_id, reason))
        self._finish(block_id)

    def _finish(self, block_id: int) -> None:
        self._blocks.pop(block_id, None)
        self._finished[block_id] = None
        while len(self._finished) > 64:
            self._finished.pop(next(iter(self._finished)))

    def tick(self, now: float) -> Progress:
        """Ask again for what is still missing, and give up blocks that waited too long."""
        progress = Progress()
        for block_id, block in list(self._blocks.items()):
            if now - block.started > self.give_up_after_s:
                self._drop(block_id, f"incomplete after {self.give_up_after_s:g} s "
                                     f"({len(block.chunks)} data packets, {block.resend_rounds} resend rounds)",
                           progress)
            elif now - block.last_seen >= self.resend_after_s:
                self._ask(block_id, block, now, progress)
        return progress

    def pending_ids(self) -> list[int]:
        """Block ids begun and not yet complete or given up."""
        return list(self._blocks)
