"""Streaming side of the simulated USB3 Vision camera: frame clock, SIRM and block transfers.

Single-threaded building blocks; the camera holds the lock, waits and renders:

- :class:`FrameScheduler` decides which frame the sensor offers next. Free-run: frame k is exposed
  from ``t0 + k / rate`` and complete one period later; a host that reads late gets the newest
  complete frame and the ones before it are skipped (block ids jump). Triggered: each accepted
  TriggerSoftware queues one frame (at most 2 waiting), complete ``exposure`` after the trigger.
- :class:`StreamInterface` holds the SIRM registers the host writes and the transfers of the block
  in flight: one leader, ``count`` payload transfers of ``size`` bytes, final transfer 1 and 2 (if
  non-zero), one trailer. Every payload slot is sent even if the image ran out (then the transfer is
  short, possibly empty); image bytes that do not fit the slots are discarded and the trailer says
  so (status DATA_DISCARDED, valid_payload_size = bytes sent).
- ``encode_leader`` / ``encode_trailer`` / ``encode_payload``: wire forms of the sheet.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.u3v.registers import GenCPStatus

LEADER_MAGIC = 0x4C563355
TRAILER_MAGIC = 0x54563355
PAYLOAD_TYPE_IMAGE = 0x0001
_LEADER = struct.Struct("<IHHQHHQIIIIIHH")
_TRAILER = struct.Struct("<IHHQHHQI")
LEADER_SIZE = _LEADER.size  # 52
TRAILER_SIZE = _TRAILER.size  # 32

PIXEL_FORMATS: Mapping[str, int] = MappingProxyType({"Mono8": 0x0108_0001, "Mono12": 0x0110_0005,
                                                     "Mono16": 0x0110_0007})
_BYTES_PER_PIXEL: Mapping[int, int] = MappingProxyType({0x0108_0001: 1, 0x0110_0005: 2, 0x0110_0007: 2})
_MAX_VALUE: Mapping[int, int] = MappingProxyType({0x0108_0001: 255, 0x0110_0005: 4095, 0x0110_0007: 65535})
MAX_TRIGGERS_QUEUED = 2

TransferKind = Literal["leader", "payload", "trailer"]

# SIRM field offsets
SI_INFO, SI_CONTROL, SI_REQ_PAYLOAD, SI_REQ_LEADER, SI_REQ_TRAILER = 0x00, 0x04, 0x08, 0x10, 0x14
SI_MAX_LEADER, SI_TRANSFER_SIZE, SI_TRANSFER_COUNT, SI_FINAL1, SI_FINAL2, SI_MAX_TRAILER = (
    0x18, 0x1C, 0x20, 0x24, 0x28, 0x2C)
_HOST_WRITTEN = (SI_MAX_LEADER, SI_TRANSFER_SIZE, SI_TRANSFER_COUNT, SI_FINAL1, SI_FINAL2, SI_MAX_TRAILER)
_ALIGNED = (SI_TRANSFER_SIZE, SI_FINAL1, SI_FINAL2)


@dataclass(frozen=True)
class ImageFormat:
    """Geometry and pixel format of one image (PFNC code)."""

    width: int
    height: int
    pixel_format: int

    @property
    def bytes_per_pixel(self) -> int:
        """1 for Mono8, 2 for Mono12 (16-bit container) and Mono16."""
        return _BYTES_PER_PIXEL[self.pixel_format]

    @property
    def payload_size(self) -> int:
        """Image payload in bytes (no row padding)."""
        return self.width * self.height * self.bytes_per_pixel


def encode_leader(block_id: int, timestamp_ns: int, fmt: ImageFormat) -> bytes:
    """Image leader (52 bytes): magic, size, block id, payload type, timestamp, format, geometry."""
    return _LEADER.pack(LEADER_MAGIC, 0, LEADER_SIZE, block_id, 0, PAYLOAD_TYPE_IMAGE, timestamp_ns,
                        fmt.pixel_format, fmt.width, fmt.height, 0, 0, 0, 0)


def encode_trailer(block_id: int, valid_payload_size: int, size_y: int, status: int = 0) -> bytes:
    """Image trailer (32 bytes): magic, size, block id, status, valid payload bytes, rows."""
    return _TRAILER.pack(TRAILER_MAGIC, 0, TRAILER_SIZE, block_id, status, 0, valid_payload_size, size_y)


def encode_payload(pixels: NDArray[np.generic], fmt: ImageFormat) -> bytes:
    """Row-major payload: Mono8 one byte, Mono12/Mono16 two bytes little-endian per pixel.

    Values are sent as the renderer gave them, saturated to the format's range (0..255, 0..4095,
    0..65535); ``pixels`` must be an integer array of shape (height, width).
    """
    if pixels.shape != (fmt.height, fmt.width):
        raise ValueError(f"renderer returned shape {pixels.shape}, the camera streams (height, width) = "
                         f"({fmt.height}, {fmt.width})")
    if not np.issubdtype(pixels.dtype, np.integer):
        raise ValueError(f"renderer returned dtype {pixels.dtype}, expected uint8 or uint16 counts")
    clipped = np.clip(pixels, 0, _MAX_VALUE[fmt.pixel_format])
    dtype = np.uint8 if fmt.bytes_per_pixel == 1 else np.dtype("<u2")
    return np.ascontiguousarray(clipped, dtype=dtype).tobytes()


def corrupt_transfer(data: bytes, how: Literal["magic", "block_id", "size"]) -> bytes:
    """A leader or trailer damaged one way: bad magic, block id + 1, or cut to 20 bytes."""
    if how == "magic":
        return struct.pack("<I", 0xDEADBEEF) + data[4:]
    if how == "block_id":
        block_id = struct.unpack_from("<Q", data, 8)[0]
        return data[:8] + struct.pack("<Q", (block_id + 1) & 0xFFFF_FFFF_FFFF_FFFF) + data[16:]
    return data[:20]


@dataclass(frozen=True)
class ScheduledFrame:
    """A frame the host is about to receive: its block id, exposure start (device ns), frames skipped."""

    block_id: int
    timestamp_ns: int
    skipped: int


class FrameScheduler:
    """Free-run clock and software-trigger queue; all times are device time in ns."""

    def __init__(self) -> None:
        self.running = False
        self._triggered = False
        self._t0 = 0
        self._period = 1
        self._next_index = 0  # free-run: lowest frame index neither sent nor skipped
        self._triggers: deque[tuple[int, int]] = deque()  # (exposure start, ready time)
        self._next_block = 0
        self._produced_before = 0  # frames produced in earlier acquisitions
        self.frames_skipped = 0
        self.triggers_ignored = 0

    def start(self, now_ns: int, frame_rate_hz: float, triggered: bool) -> None:
        """AcquisitionStart: block ids restart at 0."""
        self.running, self._triggered = True, triggered
        self._t0, self._period = now_ns, max(1, round(1e9 / frame_rate_hz))
        self._next_index = self._next_block = 0
        self._triggers.clear()

    def stop(self, now_ns: int) -> None:
        """AcquisitionStop: no new frames; waiting triggered frames are dropped."""
        if self.running:
            self._produced_before += self._produced_now(now_ns)
        self.running = False
        self._triggers.clear()

    def trigger(self, now_ns: int, exposure_ns: int) -> bool:
        """TriggerSoftware; False (and counted) when not acquiring or 2 frames already wait."""
        if not self.running or not self._triggered or len(self._triggers) >= MAX_TRIGGERS_QUEUED:
            self.triggers_ignored += 1
            return False
        self._triggers.append((now_ns, now_ns + exposure_ns))
        return True

    def take(self, now_ns: int) -> ScheduledFrame | None:
        """The frame to send now, or None if none is complete yet."""
        if not self.running:
            return None
        if self._triggered:
            if not self._triggers or self._triggers[0][1] > now_ns:
                return None
            start, _ = self._triggers.popleft()
            frame = ScheduledFrame(self._next_block, start, 0)
        else:
            newest = (now_ns - self._t0) // self._period - 1
            if newest < self._next_index:
                return None
            skipped = newest - self._next_index
            self._next_index = newest + 1
            self.frames_skipped += skipped
            frame = ScheduledFrame(newest, self._t0 + newest * self._period, skipped)
        self._next_block = frame.block_id + 1
        return frame

    def next_ready_ns(self) -> int | None:
        """When the next frame completes (device ns), or None if no frame is coming by itself."""
        if not self.running:
            return None
        if self._triggered:
            return self._triggers[0][1] if self._triggers else None
        return self._t0 + (self._next_index + 1) * self._period

    def _produced_now(self, now_ns: int) -> int:
        if self._triggered:
            return self._next_block + sum(1 for _, ready in self._triggers if ready <= now_ns)
        return max(0, (now_ns - self._t0) // self._period)

    def frames_produced(self, now_ns: int) -> int:
        """Frames the sensor completed so far, over all acquisitions."""
        return self._produced_before + (self._produced_now(now_ns) if self.running else 0)


class StreamInterface:
    """SIRM registers, the endpoint halt state and the transfers of the block in flight.

    Parameters
    ----------
    alignment_log2
        SI info alignment: transfer sizes must be multiples of ``2**alignment_log2`` bytes.
    """

    def __init__(self, alignment_log2: int = 0) -> None:
        self._alignment_log2 = alignment_log2
        self.enabled = False
        self.halted = False
        self._host = dict.fromkeys(_HOST_WRITTEN, 0)
        self._transfers: deque[tuple[TransferKind, bytes]] = deque()

    def read_register(self, offset: int, fmt: ImageFormat) -> int:
        """SIRM field value; the required sizes follow the current image format."""
        fixed = {SI_INFO: self._alignment_log2 << 24, SI_CONTROL: int(self.enabled),
                 SI_REQ_PAYLOAD: fmt.payload_size, SI_REQ_LEADER: LEADER_SIZE, SI_REQ_TRAILER: TRAILER_SIZE}
        return fixed[offset] if offset in fixed else self._host[offset]

    def write_register(self, offset: int, value: int, fmt: ImageFormat) -> GenCPStatus:
        """Host write to a SIRM field (transfer sizes only while the stream is disabled)."""
        if offset == SI_CONTROL:
            enable = bool(value & 1)
            if enable and not self.enabled and not self._consistent(fmt):
                return GenCPStatus.SI_REGISTERS_INCONSISTENT
            if not enable:
                self._transfers.clear()
            self.enabled = enable
            return GenCPStatus.SUCCESS
        if self.enabled:
            return GenCPStatus.ACCESS_DENIED
        if offset in _ALIGNED and value % (1 << self._alignment_log2):
            return GenCPStatus.SI_PAYLOAD_SIZE_NOT_ALIGNED
        self._host[offset] = value
        return GenCPStatus.SUCCESS

    def _consistent(self, fmt: ImageFormat) -> bool:
        h = self._host
        capacity = h[SI_TRANSFER_SIZE] * h[SI_TRANSFER_COUNT] + h[SI_FINAL1] + h[SI_FINAL2]
        return (h[SI_MAX_LEADER] >= LEADER_SIZE and h[SI_MAX_TRAILER] >= TRAILER_SIZE
                and capacity >= fmt.payload_size and (h[SI_TRANSFER_SIZE] > 0 or h[SI_TRANSFER_COUNT] == 0))

    def payload_slots(self) -> list[int]:
        """Sizes of the payload transfers of one block, as configured by the host."""
        h = self._host
        slots = [h[SI_TRANSFER_SIZE]] * h[SI_TRANSFER_COUNT]
        return slots + [s for s in (h[SI_FINAL1], h[SI_FINAL2]) if s]

    def begin_block(self, frame: ScheduledFrame, fmt: ImageFormat, payload: bytes) -> None:
        """Queue leader, payload transfers and trailer of one block."""
        view = memoryview(payload)
        transfers: deque[tuple[TransferKind, bytes]] = deque([("leader", encode_leader(frame.block_id,
                                                                                      frame.timestamp_ns, fmt))])
        sent = 0
        for slot in self.payload_slots():
            chunk = bytes(view[sent:sent + slot])
            sent += len(chunk)
            transfers.append(("payload", chunk))
        status = GenCPStatus.SUCCESS if sent == len(payload) else GenCPStatus.DATA_DISCARDED
        row_bytes = fmt.width * fmt.bytes_per_pixel
        transfers.append(("trailer", encode_trailer(frame.block_id, sent, sent // row_bytes, status)))
        self._transfers = transfers

    def has_pending(self) -> bool:
        """True while transfers of the block in flight remain."""
        return bool(self._transfers)

    def next_transfer(self) -> tuple[TransferKind, bytes]:
        """Pop the next transfer of the block in flight."""
        return self._transfers.popleft()

    def clear_halt(self) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT): the endpoint runs again, the interrupted block is dropped."""
        self.halted = False
        self._transfers.clear()

    def reset(self) -> None:
        """Power-on state: stream disabled, transfer sizes zero."""
        self.enabled = self.halted = False
        self._host = dict.fromkeys(_HOST_WRITTEN, 0)
        self._transfers.clear()
