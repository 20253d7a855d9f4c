"""USB3 Vision stream: bulk transfers assembled into checked image blocks, host side, without I/O.

A block is one leader transfer, the payload transfers and one trailer transfer;
:class:`BlockAssembler` is the state machine that follows them and resynchronises after trouble.
The wire layouts of the parts, their parsers and the payload decoder live in
:mod:`~wavestack.drivers.u3v.image_block` and are re-exported here.

Reference: USB3 Vision 1.0, chapter "Streaming".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.u3v.bootstrap import TransferSizes
from wavestack.drivers.u3v.image_block import (LEADER_MAGIC, LEADER_SIZE, PAYLOAD_TYPE_IMAGE, PIXEL_FORMATS,
                                               TRAILER_MAGIC, TRAILER_SIZE, Leader, Trailer, check_block,
                                               decode_pixels, is_leader, is_trailer, parse_leader, parse_trailer,
                                               pixel_format_code, pixel_format_name)

__all__ = [
    "LEADER_MAGIC", "LEADER_SIZE", "PAYLOAD_TYPE_IMAGE", "PIXEL_FORMATS", "TRAILER_MAGIC", "TRAILER_SIZE",
    "AssembledBlock", "BlockAssembler", "DiscardedBlock", "Leader", "Trailer", "check_block", "decode_pixels",
    "is_leader", "is_trailer", "parse_leader", "parse_trailer", "pixel_format_code", "pixel_format_name",
]


@dataclass(frozen=True)
class AssembledBlock:
    """A complete, checked image block.

    Attributes
    ----------
    leader
        The block's leader (block id, timestamp, pixel format, sizes).
    pixels
        Image, shape (size_y, size_x), uint8 (Mono8) or uint16 (Mono12, Mono16).
    """

    leader: Leader
    pixels: NDArray[np.generic]


@dataclass(frozen=True)
class DiscardedBlock:
    """A block (or a run of transfers) thrown away while resynchronising.

    Attributes
    ----------
    block_id
        The leader's block id, or ``None`` if no valid leader was seen.
    reason
        What was wrong.
    """

    block_id: int | None
    reason: str


class BlockAssembler:
    """Turns stream transfers into image blocks; resynchronises on the next leader after trouble.

    Pure state machine, no I/O: the caller reads one bulk transfer of :meth:`next_read_size` bytes,
    feeds it, and gets an :class:`AssembledBlock`, a :class:`DiscardedBlock` or ``None`` (more
    transfers needed). A transfer that is not a valid leader while waiting for one starts a
    "skipping" run, reported once as discarded; a leader arriving mid-block discards the unfinished
    block and starts the new one; a trailer arriving early (short payload) ends the block, which
    then fails the size check.

    Parameters
    ----------
    sizes
        The transfer sizes written into the SIRM (see ``bootstrap.compute_transfer_sizes``).
    payload_limit
        The SIRM's required payload size at stream start, bytes.
    device
        Device name for messages.
    """

    def __init__(self, sizes: TransferSizes, payload_limit: int, device: str) -> None:
        self._sizes = sizes
        self._payload_limit = payload_limit
        self._device = device
        self._small = max(sizes.max_leader_size, sizes.max_trailer_size, LEADER_SIZE, TRAILER_SIZE)
        self._largest = max(self._small, sizes.payload_size, sizes.final1_size, sizes.final2_size)
        self._capacity = sizes.payload_capacity
        self._leader: Leader | None = None
        self._chunks: list[bytes] = []
        self._received = 0
        self._transfers = 0
        self._skipping = False

    @property
    def in_block(self) -> bool:
        """Whether a leader was accepted and its trailer is still awaited."""
        return self._leader is not None

    def next_read_size(self) -> int:
        """Buffer size for the next bulk read, bytes.

        Waiting for a leader, the largest transfer (so a resynchronising read never overflows);
        inside a block, the size of the expected transfer, at least the leader/trailer size.
        """
        if self._leader is None:
            return self._largest
        sizes = self._sizes
        index = self._transfers
        finals = [size for size in (sizes.final1_size, sizes.final2_size) if size]
        if index < sizes.payload_count:
            expected = sizes.payload_size
        elif index - sizes.payload_count < len(finals):
            expected = finals[index - sizes.payload_count]
        else:
            expected = 0  # the trailer is next
        return max(expected, self._small)

    def abort(self, reason: str) -> DiscardedBlock | None:
        """Give up the current block (e.g. after a stall) and skip to the next leader."""
        discarded = DiscardedBlock(self._leader.block_id, reason) if self._leader is not None else None
        self._reset(skipping=True)
        return discarded

    def _reset(self, *, skipping: bool) -> None:
        self._leader = None
        self._chunks = []
        self._received = 0
        self._transfers = 0
        self._skipping = skipping

    def _skip(self, reason: str) -> DiscardedBlock | None:
        first = not self._skipping
        self._reset(skipping=True)
        return DiscardedBlock(None, reason) if first else None

    def _try_leader(self, transfer: bytes) -> Leader | str:
        try:
            leader = parse_leader(transfer, self._device)
            needed = leader.expected_payload_size(self._device)
        except ProtocolError as exc:
            return exc.detail
        if needed > min(self._payload_limit, self._capacity):
            return (f"block {leader.block_id}: a {leader.size_x}x{leader.size_y} image needs {needed} B, "
                    f"more than the configured payload of {self._payload_limit} B")
        return leader

    def _begin(self, leader: Leader) -> None:
        self._reset(skipping=False)
        self._leader = leader

    def feed(self, transfer: bytes) -> AssembledBlock | DiscardedBlock | None:
        """Consume one bulk transfer; see the class description for the outcomes."""
        transfer = bytes(transfer)
        current = self._leader
        if current is None:
            if not is_leader(transfer) or len(transfer) > self._small:
                return self._skip(f"expected a leader, got a {len(transfer)}-byte transfer")
            leader = self._try_leader(transfer)
            if isinstance(leader, str):
                return self._skip(f"corrupt leader: {leader}")
            self._begin(leader)
            return None
        if is_trailer(transfer) and len(transfer) <= self._small:
            return self._finish(current, transfer)
        if is_leader(transfer) and len(transfer) <= self._small:
            leader = self._try_leader(transfer)
            if isinstance(leader, Leader):
                self._begin(leader)
                return DiscardedBlock(current.block_id, f"block {current.block_id}: no trailer before the leader "
                                                        f"of block {leader.block_id}")
        self._chunks.append(transfer)
        self._received += len(transfer)
        self._transfers += 1
        if self._received > self._capacity:
            self._reset(skipping=True)
            return DiscardedBlock(current.block_id, f"block {current.block_id}: more than {self._capacity} "
                                                    f"payload bytes without a trailer")
        return None

    def _finish(self, leader: Leader, transfer: bytes) -> AssembledBlock | DiscardedBlock:
        payload = b"".join(self._chunks)
        self._reset(skipping=False)
        try:
            trailer = parse_trailer(transfer, self._device)
            check_block(leader, trailer, len(payload), self._payload_limit, self._device)
            pixels = decode_pixels(payload, leader, self._device)
        except ProtocolError as exc:
            return DiscardedBlock(leader.block_id, exc.detail)
        return AssembledBlock(leader, pixels)
