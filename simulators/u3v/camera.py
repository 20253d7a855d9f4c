"""The simulated USB3 Vision camera: register space, GenCP, streaming and faults behind one lock.

:class:`SimulatedU3VCamera` is the device; :class:`~.backend.SimulatedUsbBackend` puts it on a
simulated bus that the real ``usb.core.find`` enumerates. The camera starts no thread: the free-run
clock is computed from the monotonic clock when the host reads, and a read waits on a condition
variable (released while waiting and while the renderer runs), so a stream reader thread and a
control thread can use the camera at the same time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wavestack.simulators.genicam import PERSONALITIES, read_vendor_xml
from wavestack.simulators.u3v.descriptors import (EP_STREAM_IN, DeviceUnplugged, EndpointHalted, TransferOverflow,
                                                  TransferTimeout)
from wavestack.simulators.u3v.gencp_device import GenCPDevice
from wavestack.simulators.u3v.registers import FEATURES, DeviceIdentity, GenCPStatus, build_register_map
from wavestack.simulators.u3v.settings import (MAX_IMAGE_SIDE, CorruptionKind, FrameRenderer, U3VSimCounters,
                                               U3VSimFaults, U3VSimSettings)
from wavestack.simulators.u3v.stream_device import (PIXEL_FORMATS, SI_CONTROL, FrameScheduler, ImageFormat,
                                                    ScheduledFrame, StreamInterface, corrupt_transfer,
                                                    encode_payload)

__all__ = ["MAX_IMAGE_SIDE", "TRUTH_HISTORY", "CorruptionKind", "FrameRenderer", "SimulatedU3VCamera",
           "U3VSimCounters", "U3VSimFaults", "U3VSimSettings"]

_log = logging.getLogger(__name__)

TRUTH_HISTORY = 64  # ground truths kept, newest block ids
_LOCKED_WHILE_ACQUIRING = frozenset({"Width", "Height", "PixelFormat", "TriggerMode"})
# the features TLParamsLocked locks (SFNC: the transport layer's parameters, those that change the payload)
_LOCKED_BY_TL = frozenset(spec.name for spec in FEATURES if spec.locked_by == "TLParamsLocked")


@dataclass(frozen=True)
class _RenderJob:
    frame: ScheduledFrame
    fmt: ImageFormat
    exposure_us: float
    render: FrameRenderer
    generation: int


class SimulatedU3VCamera:
    """A USB3 Vision camera seen from the device side of the wire.

    Parameters
    ----------
    settings
        Power-on configuration.
    render
        Called once per streamed block (lazily, when the host reads its leader; skipped frames are
        never rendered).

    Notes
    -----
    The ``write_control``/``read_control``/``read_stream``/``clear_halt``/``reset`` methods are the
    transfer entry points of :class:`~.backend.SimulatedUsbBackend`; each takes the plug session
    the host's handle was opened in and raises :class:`~.descriptors.DeviceUnplugged` if the
    device is unplugged or was replugged since (a replug is a new enumeration, as on a real bus).
    """

    def __init__(self, settings: U3VSimSettings, render: FrameRenderer) -> None:
        self._settings = settings
        self._render = render
        self.faults = U3VSimFaults()
        self._cond = threading.Condition(threading.RLock())
        self._reader_lock = threading.Lock()
        self._epoch_ns = time.monotonic_ns()
        self._plugged, self._session, self._generation = True, 0, 0
        self._scheduler = FrameScheduler()
        self._stream = StreamInterface(settings.payload_alignment_log2)
        self._truths: OrderedDict[int, Any] = OrderedDict()
        self._blocks_sent = self._commands_before = 0
        self._identity = DeviceIdentity(
            manufacturer=settings.manufacturer, model=settings.model, family="wavestack simulators",
            device_version="1.0.0", manufacturer_info="simulated device, no hardware", serial=settings.serial,
            max_response_time_ms=settings.max_response_time_ms, max_command_bytes=settings.max_transfer_bytes,
            max_ack_bytes=settings.max_transfer_bytes)
        self._power_on()

    # --- test-facing API -------------------------------------------------------------------
    @property
    def settings(self) -> U3VSimSettings:
        """Power-on configuration."""
        return self._settings

    @property
    def plugged(self) -> bool:
        """True while the camera is on the bus."""
        return self._plugged

    @property
    def session(self) -> int:
        """Plug session: 0 at construction, +1 per replug."""
        return self._session

    @property
    def counters(self) -> U3VSimCounters:
        """Frames produced, skipped by the free-run clock, blocks sent, triggers ignored, commands."""
        with self._cond:
            s = self._scheduler
            return U3VSimCounters(s.frames_produced(self._now()), s.frames_skipped, self._blocks_sent,
                                  s.triggers_ignored, self._commands_before + self._gencp.commands_received)

    def truth(self, block_id: int) -> Any:
        """Ground truth the renderer returned for ``block_id`` (the last 64 streamed blocks)."""
        with self._cond:
            if block_id not in self._truths:
                raise KeyError(f"no ground truth for block {block_id}; kept: {list(self._truths)}")
            return self._truths[block_id]

    def set_size(self, width: int, height: int, render: FrameRenderer | None = None) -> None:
        """Change the image size as if Width/Height had been written (also while acquiring).

        Parameters
        ----------
        width, height
            New size, pixels (1..16384); applies from the next block.
        render
            Optional renderer to use from the next block on (one that renders the new size).
        """
        if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
            raise ValueError(f"set_size: width/height must lie in 1..{MAX_IMAGE_SIDE}, got {width} x {height}")
        with self._cond:
            self._fmt = replace(self._fmt, width=int(width), height=int(height))
            if render is not None:
                self._render = render

    def unplug(self) -> None:
        """Pull the cable: every call fails with ENODEV and enumeration no longer lists the camera."""
        with self._cond:
            self._plugged = False
            self._scheduler.stop(self._now())
            self._generation += 1
            self._gencp.clear()
            self._stream.reset()
            self._cond.notify_all()
        _log.info("simulated camera %s unplugged", self._settings.serial)

    def replug(self) -> None:
        """Plug the cable back: a powered-on camera, enumerated anew (old handles stay dead)."""
        with self._cond:
            if self._plugged:
                return
            self._session += 1
            self._power_on()
            self._plugged = True
            self._cond.notify_all()
        _log.info("simulated camera %s replugged (session %d)", self._settings.serial, self._session)

    # --- transfer entry points (used by the backend) -----------------------------------------
    def is_present(self, session: int) -> bool:
        """True if a handle opened in ``session`` still reaches the device."""
        return self._plugged and session == self._session

    def write_control(self, data: bytes, session: int) -> int:
        """Bulk OUT on EP 0x01: one GenCP command. Returns the bytes accepted."""
        with self._cond:
            self._check(session)
            self._gencp.receive(bytes(data), self._now(), max(0, int(self.faults.pending_ack_ms)))
            self._cond.notify_all()
            return len(data)

    def read_control(self, max_bytes: int, timeout_ms: int, session: int) -> bytes:
        """Bulk IN on EP 0x81: the next acknowledge (timeout 0 waits forever, as libusb)."""
        deadline = self._deadline(timeout_ms)
        with self._cond:
            while True:
                self._check(session)
                now = self._now()
                packet = self._gencp.take(now)
                if packet is not None:
                    if len(packet) > max_bytes:
                        raise TransferOverflow(f"acknowledge of {len(packet)} bytes, host buffer {max_bytes}")
                    return packet
                if deadline is not None and now >= deadline:
                    raise TransferTimeout("no acknowledge")
                self._wait(_earliest(self._gencp.next_ready_ns(), deadline))

    def read_stream(self, max_bytes: int, timeout_ms: int, session: int) -> bytes:
        """Bulk IN on EP 0x82: the next leader, payload or trailer transfer of the stream."""
        deadline = self._deadline(timeout_ms)
        wait_s = -1 if deadline is None else max(0.0, (deadline - self._now()) / 1e9)
        if not self._reader_lock.acquire(timeout=wait_s):
            raise TransferTimeout("another read holds the stream endpoint")
        try:
            while True:
                with self._cond:
                    self._check(session)
                    ready = self._stream_ready(deadline, session)
                    if ready is None:
                        return self._deliver(max_bytes)
                    job = ready
                pixels, truth = job.render(job.frame.block_id, job.frame.timestamp_ns, job.exposure_us)
                payload = encode_payload(np.asarray(pixels), job.fmt)
                with self._cond:
                    self._check(session)
                    if job.generation != self._generation:
                        continue  # acquisition or stream state changed while rendering: frame lost
                    self._stream.begin_block(job.frame, job.fmt, payload)
                    self._blocks_sent += 1
                    self._truths[job.frame.block_id] = truth
                    while len(self._truths) > TRUTH_HISTORY:
                        self._truths.popitem(last=False)
                    return self._deliver(max_bytes)
        finally:
            self._reader_lock.release()

    def clear_halt(self, endpoint: int, session: int) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT); on the stream endpoint also drops the block in flight."""
        with self._cond:
            self._check(session)
            if endpoint == EP_STREAM_IN:
                self._stream.clear_halt()
            self._cond.notify_all()

    def reset(self, session: int) -> None:
        """USB port reset: the device returns to its power-on state (the handle stays valid)."""
        with self._cond:
            self._check(session)
            self._power_on()
            self._cond.notify_all()

    # --- internals ----------------------------------------------------------------------------
    def _now(self) -> int:
        return time.monotonic_ns() - self._epoch_ns

    def _deadline(self, timeout_ms: int) -> int | None:
        return None if timeout_ms <= 0 else self._now() + int(timeout_ms) * 1_000_000

    def _check(self, session: int) -> None:
        if not self.is_present(session):
            raise DeviceUnplugged(f"camera {self._settings.serial} is not on the bus (session {session})")

    def _wait(self, until_ns: int | None) -> None:
        self._cond.wait(None if until_ns is None else max(0.0, (until_ns - self._now()) / 1e9))

    def _power_on(self) -> None:
        s = self._settings
        self._fmt = ImageFormat(s.width, s.height, PIXEL_FORMATS[s.pixel_format])
        self._exposure_us, self._trigger_mode = float(s.exposure_us), 0
        self._acquisition_mode, self._tl_params_locked = 0, 0
        self._scheduler.stop(self._now())
        self._generation += 1
        self._stream.reset()
        if hasattr(self, "_gencp"):
            self._commands_before += self._gencp.commands_received
        vendor = None
        if s.vendor is not None and s.vendor_xml is not None:
            vendor = (PERSONALITIES[s.vendor], read_vendor_xml(s.vendor_xml))
        registers = build_register_map(self._identity, _RegisterHooks(self), zipped_xml=s.zipped_xml, vendor=vendor)
        self._gencp = GenCPDevice(registers, max_command_bytes=s.max_transfer_bytes,
                                  max_ack_bytes=s.max_transfer_bytes)

    def _stream_ready(self, deadline: int | None, session: int) -> _RenderJob | None:
        """Under the lock: None if a transfer of the block in flight is due, else the frame to render."""
        if self._stream.halted:
            raise EndpointHalted("stream endpoint halted")
        if self.faults.stall_next:
            self.faults.stall_next = False
            self._stream.halted = True
            raise EndpointHalted("stream endpoint stalled (fault)")
        if self.faults.timeout_reads > 0:
            self.faults.timeout_reads -= 1
            while deadline is not None and self._now() < deadline:
                self._wait(deadline)
                self._check(session)
            raise TransferTimeout("stream read timed out (fault)")
        if self.faults.stream_paused:
            while deadline is not None and self._now() < deadline and self.faults.stream_paused:
                self._wait(deadline)
                self._check(session)
            raise TransferTimeout("stream paused (fault)")
        if self._stream.has_pending():
            return None
        while True:
            now = self._now()
            frame = self._scheduler.take(now) if self._stream.enabled else None
            if frame is not None:
                return _RenderJob(frame, self._fmt, self._exposure_us, self._render, self._generation)
            if deadline is not None and now >= deadline:
                raise TransferTimeout("no frame")
            ready = self._scheduler.next_ready_ns() if self._stream.enabled else None
            self._wait(_earliest(ready, deadline))
            self._check(session)
            if self._stream.halted:
                raise EndpointHalted("stream endpoint halted")

    def _deliver(self, max_bytes: int) -> bytes:
        kind, data = self._stream.next_transfer()
        if kind == "leader" and self.faults.corrupt_leader:
            data, self.faults.corrupt_leader = corrupt_transfer(data, self.faults.corrupt_leader), None
        elif kind == "trailer" and self.faults.corrupt_trailer:
            data, self.faults.corrupt_trailer = corrupt_transfer(data, self.faults.corrupt_trailer), None
        elif kind == "payload" and self.faults.partial_transfer:
            data, self.faults.partial_transfer = data[:len(data) // 2], False
        if len(data) > max_bytes:
            raise TransferOverflow(f"{kind} transfer of {len(data)} bytes, host buffer {max_bytes}")
        return data

    # register hooks (called by the register map, under the lock)
    def _get_feature(self, name: str) -> int | float:
        values: dict[str, int | float] = {"Width": self._fmt.width, "Height": self._fmt.height,
                                          "PixelFormat": self._fmt.pixel_format, "TriggerMode": self._trigger_mode,
                                          "ExposureTime": self._exposure_us, "PayloadSize": self._fmt.payload_size,
                                          "AcquisitionMode": self._acquisition_mode,
                                          "TLParamsLocked": self._tl_params_locked}
        return values[name]

    def _set_feature(self, name: str, value: int | float) -> GenCPStatus:
        now = self._now()
        if name in _LOCKED_WHILE_ACQUIRING and self._scheduler.running:
            return GenCPStatus.ACCESS_DENIED
        if name in _LOCKED_BY_TL and self._tl_params_locked:
            return GenCPStatus.ACCESS_DENIED
        if name == "TLParamsLocked":
            self._tl_params_locked = int(value)
        elif name == "AcquisitionMode":
            self._acquisition_mode = int(value)
        elif name == "Width":
            self._fmt = replace(self._fmt, width=int(value))
        elif name == "Height":
            self._fmt = replace(self._fmt, height=int(value))
        elif name == "PixelFormat":
            self._fmt = replace(self._fmt, pixel_format=int(value))
        elif name == "TriggerMode":
            self._trigger_mode = int(value)
        elif name == "ExposureTime":
            self._exposure_us = float(value)
        elif name == "AcquisitionStart" and not self._scheduler.running:
            self._scheduler.start(now, self._settings.frame_rate_hz, triggered=self._trigger_mode == 1)
            self._truths.clear()
            self._generation += 1
        elif name == "AcquisitionStop":
            self._scheduler.stop(now)
            self._generation += 1
        elif name == "TriggerSoftware":
            if self._trigger_mode == 0:
                return GenCPStatus.ACCESS_DENIED
            self._scheduler.trigger(now, round(self._exposure_us * 1000))
        self._cond.notify_all()
        return GenCPStatus.SUCCESS

    def _set_stream_register(self, offset: int, value: int) -> GenCPStatus:
        was_enabled = self._stream.enabled
        status = self._stream.write_register(offset, value, self._fmt)
        if offset == SI_CONTROL and self._stream.enabled != was_enabled:
            self._generation += 1
            self._cond.notify_all()
        return status


class _RegisterHooks:
    """Adapter giving the register map access to the camera's private state."""

    def __init__(self, camera: SimulatedU3VCamera) -> None:
        self._camera = camera

    def device_time_ns(self) -> int:
        return self._camera._now()

    def get_feature(self, name: str) -> int | float:
        return self._camera._get_feature(name)

    def set_feature(self, name: str, value: int | float) -> GenCPStatus:
        return self._camera._set_feature(name, value)

    def get_stream_register(self, offset: int) -> int:
        return self._camera._stream.read_register(offset, self._camera._fmt)

    def set_stream_register(self, offset: int, value: int) -> GenCPStatus:
        return self._camera._set_stream_register(offset, value)


def _earliest(a: int | None, b: int | None) -> int | None:
    """The earlier of two optional device times (None = never)."""
    if a is None:
        return b
    return a if b is None else min(a, b)
