"""GenCP control channel of a USB3 Vision camera: command/acknowledge exchanges over pyusb.

:class:`ControlChannel` owns the control endpoints of one connection. It serialises every
command / acknowledge exchange with a lock, so the user's thread and the stream thread never
interleave on the control endpoints; it honours the device's response time and PENDING_ACK, and
splits memory reads and writes into the chunk sizes the device accepts. The packets themselves are
built and parsed by the pure :mod:`~wavestack.drivers.u3v.gencp`.
"""

from __future__ import annotations

import errno
import logging
import math
import threading
import time
from collections.abc import Callable

import usb.core

from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, ProtocolError
from wavestack.drivers.u3v import gencp

logger = logging.getLogger(__name__)

_BOOT_CHUNK = 64  # READMEM size before the SBRM tells us the real limits


def _timeout_ms(seconds: float) -> int:
    return max(1, math.ceil(seconds * 1000))  # pyusb treats 0 as "wait forever"


class ControlChannel:
    """GenCP command/acknowledge exchanges on the control endpoints, one at a time (locked)."""

    def __init__(self, dev: usb.core.Device, ep_out: int, ep_in: int, name: str,
                 on_disconnect: Callable[[DeviceDisconnected], None]) -> None:
        self._dev = dev
        self._ep_out = ep_out
        self._ep_in = ep_in
        self.name = name
        self._on_disconnect = on_disconnect
        self._lock = threading.Lock()
        self._request_id = 0
        self._busy_until = 0.0  # monotonic time until which an abandoned request may keep the device busy
        self.response_time_s: float | None = None  # None until the ABRM is read: only the call's deadline
        self.read_chunk = _BOOT_CHUNK
        self.write_chunk = _BOOT_CHUNK
        self.ack_buffer = 1024

    def _usb_failure(self, exc: usb.core.USBError, what: str) -> DeviceError:
        if isinstance(exc, usb.core.USBTimeoutError):
            return DeviceTimeout(self.name, f"{what}: USB transfer timed out")
        if exc.errno == errno.ENODEV:
            error = DeviceDisconnected(self.name, f"{what}: device is gone (unplugged?)")
            self._on_disconnect(error)
            return error
        if exc.errno == errno.EPIPE:
            for ep in (self._ep_out, self._ep_in):
                try:
                    self._dev.clear_halt(ep)
                except usb.core.USBError:
                    logger.warning("%s: clear_halt(0x%02X) failed", self.name, ep)
        return ProtocolError(self.name, f"{what}: USB error {exc}")

    def transact(self, build: Callable[[int], bytes], expected_ack: int, deadline: float,
                 what: str) -> gencp.Acknowledge:
        """Send the packet ``build(request_id)`` and return its successful acknowledge."""
        if not self._lock.acquire(timeout=max(0.0, deadline - time.monotonic())):
            raise DeviceTimeout(self.name, f"{what}: control channel stayed busy until the call's timeout")
        try:
            self._request_id = gencp.next_request_id(self._request_id)
            return self._exchange(build(self._request_id), self._request_id, expected_ack, deadline, what)
        finally:
            self._lock.release()

    def _exchange(self, packet: bytes, request_id: int, expected_ack: int, deadline: float,
                  what: str) -> gencp.Acknowledge:
        try:
            self._dev.write(self._ep_out, packet, timeout=_timeout_ms(deadline - time.monotonic()))
        except usb.core.USBError as exc:
            raise self._usb_failure(exc, what) from None
        window = self.response_time_s
        # what the device promises: its response time, counted from when it finished an abandoned
        # request it may still be working on; PENDING_ACK replaces the promise
        promised = None if window is None else max(time.monotonic(), self._busy_until) + window
        while True:
            now = time.monotonic()
            limit = deadline if promised is None else min(deadline, promised)
            if now >= limit:
                if promised is not None and promised > now:
                    self._busy_until = promised  # it may still answer; the next command queues behind
                    raise DeviceTimeout(self.name, f"{what}: expected an acknowledge to request {request_id} "
                                                   f"within the call's timeout, got none")
                raise DeviceTimeout(self.name, f"{what}: expected an acknowledge to request {request_id} "
                                               f"within the device's response time, got none")
            try:
                data = self._dev.read(self._ep_in, self.ack_buffer, timeout=_timeout_ms(limit - now))
            except usb.core.USBTimeoutError:
                continue
            except usb.core.USBError as exc:
                raise self._usb_failure(exc, what) from None
            ack = gencp.parse_acknowledge(bytes(data), self.name)
            if ack.request_id != request_id:
                logger.info("%s: discarding stale acknowledge to request %d (waiting for %d)",
                            self.name, ack.request_id, request_id)
                continue
            if ack.command_id == gencp.PENDING_ACK and ack.succeeded:
                extra_s = gencp.pending_timeout_ms(ack, self.name) / 1000
                promised = time.monotonic() + extra_s
                logger.debug("%s: %s pending for up to %.0f ms", self.name, what, extra_s * 1000)
                continue
            self._busy_until = 0.0
            if not ack.succeeded:
                raise ProtocolError(self.name, f"{what}: device answered {gencp.status_name(ack.status)}")
            if ack.command_id != expected_ack:
                raise ProtocolError(self.name, f"{what}: expected acknowledge 0x{expected_ack:04X}, "
                                               f"got 0x{ack.command_id:04X}")
            return ack

    def read(self, address: int, length: int, deadline: float, what: str) -> bytes:
        """``length`` bytes at ``address``, in chunks the device accepts."""
        out = bytearray()
        while len(out) < length:
            size = min(self.read_chunk, length - len(out))
            where = address + len(out)
            ack = self.transact(lambda rid: gencp.encode_readmem(rid, where, size), gencp.READMEM_ACK, deadline,
                                f"{what}: READMEM 0x{where:X}")
            if len(ack.scd) != size:
                raise ProtocolError(self.name, f"{what}: READMEM of {size} B at 0x{where:X} returned "
                                                f"{len(ack.scd)} B")
            out += ack.scd
        return bytes(out)

    def write(self, address: int, data: bytes, deadline: float, what: str) -> None:
        """Write ``data`` at ``address``, in chunks the device accepts."""
        for start in range(0, len(data), self.write_chunk):
            chunk = data[start:start + self.write_chunk]
            where = f"{what}: WRITEMEM 0x{address + start:X}"
            ack = self.transact(lambda rid: gencp.encode_writemem(rid, address + start, chunk), gencp.WRITEMEM_ACK,
                                deadline, where)
            written = gencp.bytes_written(ack, self.name)
            if written != len(chunk):
                raise ProtocolError(self.name, f"{where}: device wrote {written} of {len(chunk)} B")
