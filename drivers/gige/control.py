"""The GVCP control channel of one GigE Vision camera: one UDP socket, one request at a time.

Every exchange sends a command, waits for its acknowledge until the caller's deadline (resending
the same request after each :attr:`ControlChannel.retry_s`, as GigE Vision allows), discards
acknowledges of other requests, honours PENDING_ACK, and raises a typed error naming the device:
``DeviceTimeout`` when nothing answered in time (``ProtocolError`` when only wrong acknowledges
did), ``ProtocolError`` for a refused command (the GEV status by name). Any acknowledged command
also serves as the heartbeat: the device keeps the host's control privilege while they come.

:class:`GvcpPort` is the channel as the GenICam node map's register port.
"""

from __future__ import annotations

import socket
import struct
import threading
import time

from wavestack.drivers.errors import DeviceDisconnected, DeviceTimeout, ProtocolError
from wavestack.drivers.gige import gvcp

_MAX_DATAGRAM = 1500


class ControlChannel:
    """GVCP requests to one device (thread-safe).

    Parameters
    ----------
    host, port
        The device's address and GVCP port (3956 on a real camera).
    name
        Device name for messages.
    """

    def __init__(self, host: str, port: int, name: str) -> None:
        self.name = name
        self.retry_s = 0.2
        self._lock = threading.Lock()
        self._request_id = 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.connect((host, port))
        except OSError as exc:
            self._sock.close()
            raise DeviceDisconnected(name, f"cannot reach {host}:{port}: {exc}") from None
        self.wrong_acks = 0
        self.local_address = self._sock.getsockname()[0]

    def close(self) -> None:
        with self._lock:
            self._sock.close()

    def _next_id(self) -> int:
        self._request_id = self._request_id % 0xFFFF + 1
        return self._request_id

    def send_only(self, packet_of: object) -> None:
        """Send a command that is not acknowledged (PACKETRESEND); ``packet_of(request_id)`` builds it."""
        with self._lock:
            try:
                self._sock.send(packet_of(self._next_id()))  # type: ignore[operator]
            except OSError:
                pass  # a lost resend request is a lost frame, counted by the stream

    def transact(self, encode: object, answer: int, deadline: float, what: str) -> gvcp.Ack:
        """Send ``encode(request_id)`` and return its successful acknowledge.

        Raises
        ------
        DeviceTimeout
            No acknowledge of this request by ``deadline``.
        ProtocolError
            The device refused it (status named), or only acknowledges of other requests came.
        DeviceDisconnected
            The socket failed (network down, port unreachable).
        """
        with self._lock:
            request_id = self._next_id()
            packet = encode(request_id)  # type: ignore[operator]
            wrong: gvcp.WrongAck | None = None
            while True:
                now = time.monotonic()
                if now >= deadline:
                    break
                try:
                    self._sock.send(packet)
                except OSError as exc:
                    raise DeviceDisconnected(self.name, f"{what}: cannot send: {exc}") from None
                ack, wrong = self._await(request_id, answer, min(deadline, now + self.retry_s), what, wrong)
                if ack is not None:
                    if ack.status != 0:
                        raise ProtocolError(self.name, f"{what}: device answered {gvcp.status_name(ack.status)} "
                                                       f"(0x{ack.status:04X})")
                    return ack
            if wrong is not None:
                raise ProtocolError(self.name, f"{what}: only acknowledges of other requests came ({wrong.detail})")
            raise DeviceTimeout(self.name, f"{what}: no acknowledge within the timeout")

    def _await(self, request_id: int, answer: int, until: float, what: str,
               wrong: gvcp.WrongAck | None) -> tuple[gvcp.Ack | None, gvcp.WrongAck | None]:
        while True:
            remaining = until - time.monotonic()
            if remaining <= 0:
                return None, wrong
            self._sock.settimeout(remaining)
            try:
                data = self._sock.recv(_MAX_DATAGRAM)
            except TimeoutError:
                return None, wrong
            except OSError as exc:  # ICMP port unreachable: nothing listens at the device's address
                raise DeviceDisconnected(self.name, f"{what}: {exc}") from None
            try:
                ack = gvcp.parse_ack(data, self.name, answer=answer, request_id=request_id)
            except gvcp.WrongAck as exc:
                self.wrong_acks += 1
                wrong = exc
                continue
            except ProtocolError as exc:
                raise ProtocolError(self.name, f"{what}: {exc.detail}") from None
            if ack.answer == gvcp.PENDING_ACK:  # the device needs longer: wait as long as it says
                pending_ms = struct.unpack(">HH", ack.payload[:4])[1] if len(ack.payload) >= 4 else 0
                until = max(until, time.monotonic() + pending_ms / 1000)
                continue
            return ack, wrong

    # --- registers and memory ----------------------------------------------------------------------
    def read_register(self, address: int, deadline: float) -> int:
        ack = self.transact(lambda i: gvcp.encode_readreg(i, [address]), gvcp.READREG_ACK, deadline,
                            f"READREG 0x{address:X}")
        if len(ack.payload) != 4:
            raise ProtocolError(self.name, f"READREG 0x{address:X}: {len(ack.payload)} B of data; expected 4")
        return int(struct.unpack(">I", ack.payload)[0])

    def write_register(self, address: int, value: int, deadline: float) -> None:
        self.transact(lambda i: gvcp.encode_writereg(i, [(address, value)]), gvcp.WRITEREG_ACK, deadline,
                      f"WRITEREG 0x{address:X}")

    def read_memory(self, address: int, length: int, deadline: float) -> bytes:
        """``length`` bytes at ``address`` in READMEM chunks (any alignment: whole words are read)."""
        start, end = address - address % 4, address + length
        data = bytearray()
        while start + len(data) < end:
            at = start + len(data)
            count = min(gvcp.MAX_READMEM, -(-(end - at) // 4) * 4)
            ack = self.transact(lambda i, a=at, c=count: gvcp.encode_readmem(i, a, c), gvcp.READMEM_ACK, deadline,
                                f"READMEM 0x{at:X}")
            if len(ack.payload) != 4 + count or struct.unpack(">I", ack.payload[:4])[0] != at:
                raise ProtocolError(self.name, f"READMEM 0x{at:X}: acknowledge of {len(ack.payload)} B for "
                                               f"{count} B, or of another address")
            data += ack.payload[4:]
        offset = address - start
        return bytes(data[offset:offset + length])

    def write_memory(self, address: int, data: bytes, deadline: float) -> None:
        """Store ``data`` at ``address`` (4-byte aligned, a multiple of 4 bytes) in WRITEMEM chunks."""
        if address % 4 or len(data) % 4:
            raise ProtocolError(self.name, f"WRITEMEM 0x{address:X} of {len(data)} B: GigE Vision writes whole "
                                           f"aligned words")
        for offset in range(0, len(data), gvcp.MAX_READMEM):
            chunk = data[offset:offset + gvcp.MAX_READMEM]
            self.transact(lambda i, a=address + offset, c=chunk: gvcp.encode_writemem(i, a, c), gvcp.WRITEMEM_ACK,
                          deadline, f"WRITEMEM 0x{address + offset:X}")


class GvcpPort:
    """The device's register space for the node map, every access bounded by :attr:`deadline`.

    Single aligned words go by READREG/WRITEREG, anything else by READMEM/WRITEMEM.
    """

    def __init__(self, channel: ControlChannel) -> None:
        self._channel = channel
        self.deadline = 0.0

    def read(self, address: int, length: int) -> bytes:
        if length == 4 and address % 4 == 0:
            return struct.pack(">I", self._channel.read_register(address, self.deadline))
        return self._channel.read_memory(address, length, self.deadline)

    def write(self, address: int, data: bytes) -> None:
        if len(data) == 4 and address % 4 == 0:
            self._channel.write_register(address, struct.unpack(">I", data)[0], self.deadline)
        else:
            self._channel.write_memory(address, data, self.deadline)
