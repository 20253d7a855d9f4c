"""The simulated GigE Vision camera: a GVCP server and a GVSP sender on UDP, with fault switches.

:class:`SimulatedGigECamera` answers GVCP on ``settings.host:settings.port`` (DISCOVERY,
READREG, WRITEREG, READMEM, WRITEMEM, PACKETRESEND) from one thread and streams image blocks from
another, paced at ``settings.link_rate_mbit_s``, to the address and port the host writes into
stream channel 0. The control privilege (CCP) belongs to one host at a time and lapses after the
heartbeat timeout without commands from it, which also stops a running acquisition. Any host may
read (a monitor); only the controlling host writes and asks for resends. The last blocks sent are
kept for PACKETRESEND, and at most :data:`RESEND_QUEUE` requests wait (the oldest is dropped, as a
lost request). Faults are injected through ``camera.faults``.
"""

from __future__ import annotations

import collections
import ipaddress
import logging
import random
import socket
import struct
import threading
import time
from collections import OrderedDict
from dataclasses import replace
from typing import Any

import numpy as np

from wavestack.simulators.gige import protocol as p
from wavestack.simulators.gige.registers import CCP, HEARTBEAT_TIMEOUT, MAC, SCDA0, SCP0, SCPS0, Cells, build_register_map
from wavestack.simulators.gige.settings import GigESimFaults, GigESimSettings
from wavestack.simulators.u3v import PIXEL_FORMATS, FrameRenderer, GenCPStatus
from wavestack.simulators.u3v.stream_device import FrameScheduler, ImageFormat, encode_payload

_log = logging.getLogger(__name__)
TRUTH_HISTORY = 64
RESEND_HISTORY = 8
RESEND_QUEUE = 16
_OVERSIZED = 9100
_LOCKED_WHILE_ACQUIRING = frozenset({"Width", "Height", "PixelFormat", "TriggerMode"})


class SimulatedGigECamera:
    """A GigE Vision camera seen from the device side of the wire.

    Parameters
    ----------
    settings
        Power-on configuration (where it listens, the image, a vendor personality).
    render
        ``render(block_id, device_time_ns, exposure_us) -> (pixels, truth)``, as for the USB3 Vision
        simulator; called once per block sent.

    Use as a context manager, or :meth:`start` and :meth:`stop`.
    """

    def __init__(self, settings: GigESimSettings, render: FrameRenderer) -> None:
        self.settings = settings
        self.faults = GigESimFaults()
        self._render = render
        self._lock = threading.RLock()
        self._wake = threading.Condition(self._lock)
        self._epoch_ns = time.monotonic_ns()
        self._scheduler = FrameScheduler()
        self._fmt = ImageFormat(settings.width, settings.height, PIXEL_FORMATS[settings.pixel_format])
        self._exposure_us, self._trigger_mode, self._acquisition_mode, self._tl_locked = \
            float(settings.exposure_us), 0, 0, 0
        self._cells = Cells(settings.heartbeat_timeout_ms)
        self._controller: tuple[str, int] | None = None
        self._last_command = 0.0
        self._truths: OrderedDict[int, Any] = OrderedDict()
        self._history: OrderedDict[int, list[bytes]] = OrderedDict()
        self._resends: collections.deque[tuple[int, int, int]] = collections.deque(maxlen=RESEND_QUEUE)
        self._random = random.Random(self.faults.loss_seed)
        self.counters = collections.Counter[str]()
        self._control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._control.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._control.bind((settings.host, settings.port))
        self._control.settimeout(0.05)
        self._stream = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._stream.bind((settings.host, 0))
        self.host, self.port = self._control.getsockname()
        self._registers = build_register_map(settings, _Hooks(self), self._cells,
                                             int(ipaddress.IPv4Address(self.host)))
        self._running = threading.Event()
        self._threads: list[threading.Thread] = []

    # --- life cycle ----------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """``gige://HOST:PORT`` of this camera."""
        return f"gige://{self.host}:{self.port}"

    def start(self) -> SimulatedGigECamera:
        """Start answering GVCP and streaming."""
        self._running.set()
        for target, name in ((self._serve_control, "gvcp"), (self._serve_stream, "gvsp")):
            thread = threading.Thread(target=target, name=f"gige-sim-{name} {self.settings.serial}", daemon=True)
            thread.start()
            self._threads.append(thread)
        return self

    def stop(self) -> None:
        """Stop both threads and close the sockets. Idempotent."""
        self._running.clear()
        with self._wake:
            self._wake.notify_all()
        for thread in self._threads:
            thread.join()
        self._threads.clear()
        self._control.close()
        self._stream.close()

    def __enter__(self) -> SimulatedGigECamera:
        return self.start()

    def __exit__(self, *_: object) -> None:
        self.stop()

    def truth(self, block_id: int) -> Any:
        """Ground truth of a streamed block (the last 64), by its GVSP id or the host's growing frame id."""
        key = (block_id - 1) % 0xFFFF + 1
        with self._lock:
            if key not in self._truths:
                raise KeyError(f"no ground truth for block {block_id}; kept: {list(self._truths)}")
            return self._truths[key]

    def device_time_ns(self) -> int:
        return time.monotonic_ns() - self._epoch_ns

    # --- GVCP ------------------------------------------------------------------------------------
    def _serve_control(self) -> None:
        while self._running.is_set():
            self._expire_heartbeat()
            try:
                datagram, sender = self._control.recvfrom(2048)
            except (TimeoutError, OSError):
                continue
            if self.faults.silent:
                continue
            command = p.parse_command(datagram)
            if command is None:
                continue
            self.counters["commands"] += 1
            with self._lock:
                status, payload = self._execute(command, sender)
            if command.wants_ack:
                ack_id = None
                if self.faults.wrong_ack_id > 0:
                    self.faults.wrong_ack_id -= 1
                    ack_id = (command.request_id % 0xFFFF) + 1
                self._control.sendto(p.acknowledge(status, command, payload, ack_id=ack_id), sender)

    def _expire_heartbeat(self) -> None:
        with self._lock:
            timeout_s = self._cells.values[HEARTBEAT_TIMEOUT] / 1000
            if self._controller is not None and time.monotonic() - self._last_command > timeout_s:
                _log.info("simulated GigE camera %s: heartbeat expired, control released", self.settings.serial)
                self._controller = None
                self._cells.values[CCP] = 0
                self._scheduler.stop(self.device_time_ns())
                self._wake.notify_all()

    def _execute(self, command: p.Command, sender: tuple[str, int]) -> tuple[int, bytes]:
        if sender == self._controller:
            self._last_command = time.monotonic()
        code, body = command.code, command.payload
        if code == p.DISCOVERY:
            return p.SUCCESS, self._discovery()
        if code == p.PACKETRESEND and len(body) == 12:
            if sender != self._controller:
                self.counters["resends_refused"] += 1
                return p.ACCESS_DENIED, b""
            _, block, first, last = struct.unpack(">HHII", body)
            self._resends.append((block, first, last))
            self._wake.notify_all()
            return p.SUCCESS, b""
        if code == p.READREG and body and len(body) % 4 == 0:
            values = b""
            for (address,) in struct.iter_unpack(">I", body):
                status, data = self._registers.read(address, 4)
                if status != GenCPStatus.SUCCESS:
                    return int(status), b""
                values += data
            return p.SUCCESS, values
        if code == p.READMEM and len(body) == 8:
            address, _, count = struct.unpack(">IHH", body)
            if address % 4 or count % 4 or not 0 < count <= 536:
                return p.BAD_ALIGNMENT, b""
            status, data = self._registers.read(address, count)
            return (p.SUCCESS, struct.pack(">I", address) + data) if status == GenCPStatus.SUCCESS else (int(status), b"")
        if code in (p.WRITEREG, p.WRITEMEM):
            return self._write(code, body, sender)
        return (p.NOT_IMPLEMENTED if code not in (p.READREG, p.READMEM, p.PACKETRESEND) else p.INVALID_HEADER), b""

    def _write(self, code: int, body: bytes, sender: tuple[str, int]) -> tuple[int, bytes]:
        if code == p.WRITEREG:
            if not body or len(body) % 8:
                return p.INVALID_HEADER, b""
            writes = [(a, struct.pack(">I", v)) for a, v in struct.iter_unpack(">II", body)]
        else:
            if len(body) < 8 or len(body) % 4:
                return p.INVALID_HEADER, b""
            writes = [(struct.unpack(">I", body[:4])[0], body[4:])]
        for index, (address, data) in enumerate(writes):
            if not self._may_write(address, data, sender):
                return p.ACCESS_DENIED, struct.pack(">HH", 0, index)
            status, _ = self._registers.write(address, data)
            if status != GenCPStatus.SUCCESS:
                return int(status), struct.pack(">HH", 0, index)
            if address == CCP:
                value = struct.unpack(">I", data)[0]
                self._controller = sender if value else None
                self._last_command = time.monotonic()
        return p.SUCCESS, struct.pack(">HH", 0, len(writes) if code == p.WRITEREG else len(writes[0][1]))

    def _may_write(self, address: int, data: bytes, sender: tuple[str, int]) -> bool:
        """Only the controlling host writes; CCP is free to take when nobody holds it."""
        if sender == self._controller:
            return True
        return address == CCP and self._controller is None

    def _discovery(self) -> bytes:
        return p.discovery_payload(version=(2, 0), mac=MAC, ip=int(ipaddress.IPv4Address(self.host)),
                                   manufacturer=self.settings.manufacturer, model=self.settings.model,
                                   device_version="1.0.0", serial=self.settings.serial, user_name="")

    # --- features (called by the registers, under the lock) ---------------------------------------
    def get_feature(self, name: str) -> int | float:
        return {"Width": self._fmt.width, "Height": self._fmt.height, "PixelFormat": self._fmt.pixel_format,
                "TriggerMode": self._trigger_mode, "ExposureTime": self._exposure_us,
                "PayloadSize": self._fmt.payload_size, "AcquisitionMode": self._acquisition_mode,
                "TLParamsLocked": self._tl_locked}[name]

    def set_feature(self, name: str, value: int | float) -> GenCPStatus:
        now = self.device_time_ns()
        if name in _LOCKED_WHILE_ACQUIRING and self._scheduler.running:
            return GenCPStatus.ACCESS_DENIED
        if name in ("Width", "Height", "PixelFormat") and self._tl_locked:
            return GenCPStatus.ACCESS_DENIED
        if name in ("Width", "Height"):
            self._fmt = replace(self._fmt, **{name.lower(): int(value)})
        elif name == "PixelFormat":
            self._fmt = replace(self._fmt, pixel_format=int(value))
        elif name in ("TriggerMode", "AcquisitionMode", "TLParamsLocked"):
            setattr(self, {"TriggerMode": "_trigger_mode", "AcquisitionMode": "_acquisition_mode",
                           "TLParamsLocked": "_tl_locked"}[name], int(value))
        elif name == "ExposureTime":
            self._exposure_us = float(value)
        elif name == "AcquisitionStart" and not self._scheduler.running:
            self._scheduler.start(now, self.settings.frame_rate_hz, triggered=self._trigger_mode == 1)
            self._truths.clear()
        elif name == "AcquisitionStop":
            self._scheduler.stop(now)
        elif name == "TriggerSoftware":
            if self._trigger_mode == 0:
                return GenCPStatus.ACCESS_DENIED
            self._scheduler.trigger(now, round(self._exposure_us * 1000))
        self._wake.notify_all()
        return GenCPStatus.SUCCESS

    # --- GVSP ------------------------------------------------------------------------------------
    def _destination(self) -> tuple[str, int] | None:
        port, address = self._cells.values[SCP0] & 0xFFFF, self._cells.values[SCDA0]
        return (str(ipaddress.IPv4Address(address)), port) if port and address else None

    def _serve_stream(self) -> None:
        while self._running.is_set():
            job = None
            with self._wake:
                while self._running.is_set() and job is None:
                    if self._resends:
                        break
                    now = self.device_time_ns()
                    frame = self._scheduler.take(now) if self._destination() else None
                    if frame is not None:
                        job = (frame, self._fmt, self._exposure_us, self._destination(),
                               self._cells.values[SCPS0] & 0xFFFF)
                        break
                    ready = self._scheduler.next_ready_ns()
                    self._wake.wait(0.05 if ready is None else max(0.0, min(0.05, (ready - now) / 1e9)))
            self._send_resends()
            if job is not None:
                self._send_block(*job)

    def _send_block(self, frame: Any, fmt: ImageFormat, exposure_us: float, destination: tuple[str, int] | None,
                    packet_size: int) -> None:
        block_id = frame.block_id % 0xFFFF + 1
        pixels, truth = self._render(block_id, frame.timestamp_ns, exposure_us)
        payload = encode_payload(np.asarray(pixels), fmt)
        packets = p.block_packets(block_id, frame.timestamp_ns, fmt.pixel_format, fmt.width, fmt.height, payload,
                                  max(packet_size, 576) - 36)
        with self._lock:
            self._truths[block_id] = truth
            while len(self._truths) > TRUTH_HISTORY:
                self._truths.popitem(last=False)
            self._history[block_id] = packets
            while len(self._history) > RESEND_HISTORY:
                self._history.popitem(last=False)
        order = list(packets)
        if self.faults.reorder:
            for i in range(1, len(order) - 2, 2):
                order[i], order[i + 1] = order[i + 1], order[i]
        if self.faults.oversized_packet:
            self.faults.oversized_packet = False
            order[1] = order[1] + bytes(_OVERSIZED - len(order[1]))
        self.counters["blocks"] += 1
        self.counters["skipped"] += frame.skipped  # frames the free-run clock passed while this one was sent
        self._send(order, destination)

    def _send_resends(self) -> None:
        while True:
            with self._lock:
                if not self._resends:
                    return
                block, first, last = self._resends.popleft()
                packets = self._history.get(block, [])
                destination = self._destination()
            wanted = packets[first:last + 1] if first < len(packets) else []
            self.counters["resent"] += len(wanted)
            self._send(wanted, destination)

    def _send(self, packets: list[bytes], destination: tuple[str, int] | None) -> None:
        if destination is None:
            return
        rate = self.settings.link_rate_mbit_s * 125_000  # bytes per second
        started, sent = time.monotonic(), 0
        for packet in packets:
            if self.faults.silent or self.faults.stream_paused or not self._running.is_set():
                return
            if self.faults.packet_loss and self._random.random() < self.faults.packet_loss:
                self.counters["lost"] += 1
            else:
                try:
                    self._stream.sendto(packet, destination)
                except OSError:
                    return
                self.counters["packets"] += 1
            sent += len(packet) + 28
            ahead = sent / rate - (time.monotonic() - started)
            if ahead > 0.001:
                time.sleep(ahead)


class _Hooks:
    def __init__(self, camera: SimulatedGigECamera) -> None:
        self._camera = camera

    def get_feature(self, name: str) -> int | float:
        return self._camera.get_feature(name)

    def set_feature(self, name: str, value: int | float) -> GenCPStatus:
        return self._camera.set_feature(name, value)

    def device_time_ns(self) -> int:
        return self._camera.device_time_ns()
