"""The one byte link under every byte-stream device: opened from a URL, framed exchanges with a deadline.

:class:`ByteLink` *has* one byte stream to one device and knows nothing of what the bytes mean:

- **URLs.** ``tcp://HOST[:PORT]`` is a TCP connection made within the open timeout (a device
  family may give a default port: PI's GCS controllers listen on 50000); anything else goes to
  pyserial's ``serial.serial_for_url``: a serial port (``/dev/ttyUSB0``, ``COM3``), a
  pseudo-terminal path, ``socket://HOST:PORT`` (raw TCP, as behind a serial device server),
  ``rfc2217://HOST:PORT`` (a Telnet COM port server) and the simulators' ``sim://`` ports, at
  8N1 and the given baud rate. A local path is checked against the device-path allow-list just
  before it is opened (:mod:`~wavestack.drivers.device_path`).
- **Exchanges.** :meth:`ByteLink.exchange` writes a request and reads until the device's framing
  function (a pure function of the device's ``protocol`` module) finds a complete reply in the
  bytes received: ``complete(buffer) -> (reply or None, rest)``. Bytes after a reply stay for
  the next read.
- **Bounds.** Every read waits at most until the caller's deadline (in polls of ``poll_s``, so a
  deadline is kept within one poll), and holds at most ``max_reply_bytes`` bytes: more without a
  complete reply is a :class:`~wavestack.drivers.errors.ProtocolError`.
- **Errors.** No complete reply by the deadline -> ``DeviceTimeout``; a framing function's
  ``ProtocolError`` passes through; both leave the link *dirty* (late bytes of that reply could
  be taken for the next one) until :meth:`ByteLink.drain` discards input until the line has been
  quiet for ``quiet_s``. A write that does not finish -> ``DeviceTimeout``; any other I/O failure
  -> ``DeviceDisconnected``, and the link stays lost (every call says so) until :meth:`open`.

:class:`LinkedDevice` is the open, close and context-manager code every such driver shares: open
the link, run the driver's handshake, close the link again when the handshake fails.

The caller serialises access (its driver's lock). Example, a device that answers ``pong\\n``::

    link = ByteLink("socket://127.0.0.1:5000", lambda: "echo device")
    link.open(timeout_s=1.0)
    reply = link.exchange(b"ping\\n", complete=line, deadline=time.monotonic() + 1.0, during="ping")
"""

from __future__ import annotations

import logging
import re
import socket
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Self, TypeVar

import serial

from wavestack.drivers.device_path import check_device_path
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, ProtocolError

__all__ = ["ByteLink", "Framing", "LinkedDevice", "line_framing", "parse_tcp_url"]

logger = logging.getLogger(__name__)

T = TypeVar("T")
#: A device's framing function: the first complete reply in the bytes received and the bytes after it,
#: or ``(None, buffer)`` while more are needed; it may raise ``ProtocolError`` for bytes that never frame.
Framing = Callable[[bytearray], "tuple[T | None, bytes | bytearray]"]

_CHUNK = 1 << 20  # largest single read
_TCP_URL = re.compile(r"^tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[^:/\s\[\]]+)(:(?P<port>\d{1,5}))?/?$")


def parse_tcp_url(url: str, default_port: int | None = None) -> tuple[str, int] | None:
    """``(host, port)`` of a ``tcp://HOST[:PORT]`` URL, None for any other URL.

    Raises
    ------
    ValueError
        A malformed ``tcp://`` URL, a port outside 1..65535, or no port and no ``default_port``.

    Examples
    --------
    >>> parse_tcp_url("tcp://192.168.0.10", 50000), parse_tcp_url("tcp://[::1]:5555"), parse_tcp_url("/dev/ttyS0")
    (('192.168.0.10', 50000), ('::1', 5555), None)
    """
    if not url.startswith("tcp://"):
        return None
    match = _TCP_URL.fullmatch(url)
    port = None if match is None else (match.group("port") or default_port)
    if match is None or port is None or not 0 < int(port) < 65536:
        wanted = "tcp://HOST[:PORT]" if default_port is not None else "tcp://HOST:PORT"
        raise ValueError(f"expected {wanted} with a port 1..65535, got {url!r}")
    return match.group("host").strip("[]"), int(port)


def line_framing(buffer: bytearray) -> tuple[bytes | None, bytes | bytearray]:
    """Framing of replies that end at the first LF (the reply keeps its LF).

    Examples
    --------
    >>> line_framing(bytearray(b"1\\n2")), line_framing(bytearray(b"1"))
    ((b'1\\n', bytearray(b'2')), (None, bytearray(b'1')))
    """
    end = buffer.find(b"\n")
    return (None, buffer) if end < 0 else (bytes(buffer[:end + 1]), buffer[end + 1:])


class _TcpStream:
    """A connected TCP socket with the read and write calls the link uses."""

    def __init__(self, address: tuple[str, int], timeout_s: float, poll_s: float) -> None:
        self._sock = socket.create_connection(address, timeout=timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._poll_s = poll_s

    def read(self, limit: int, *, wait: bool = True) -> bytes:
        self._sock.settimeout(self._poll_s if wait else 0.0)
        try:
            chunk = self._sock.recv(limit)
        except (TimeoutError, BlockingIOError):
            return b""
        if not chunk:
            raise ConnectionResetError("the connection was closed by the device")
        return chunk

    def write(self, data: bytes, deadline: float) -> None:
        view = memoryview(data)
        while view:
            left = deadline - time.monotonic()
            if left <= 0:
                raise serial.SerialTimeoutException(f"{len(view)} of {len(data)} bytes not sent before the deadline")
            self._sock.settimeout(left)
            try:
                view = view[self._sock.send(view):]
            except TimeoutError:
                continue

    def close(self) -> None:
        self._sock.close()


class _SerialStream:
    """A pyserial port (anything ``serial_for_url`` opens) with the read and write calls the link uses."""

    def __init__(self, url: str, baudrate: int, timeout_s: float, poll_s: float) -> None:
        self._port = serial.serial_for_url(url, baudrate=baudrate, bytesize=8, parity="N", stopbits=1,
                                           timeout=poll_s, write_timeout=timeout_s)

    def read(self, limit: int, *, wait: bool = True) -> bytes:
        waiting = self._port.in_waiting
        if not waiting and not wait:
            return b""
        return bytes(self._port.read(max(1, min(limit, waiting))))

    def write(self, data: bytes, deadline: float) -> None:
        self._port.write(data)  # into the OS buffer, bounded by the port's write timeout (the open timeout)

    def close(self) -> None:
        self._port.close()


class ByteLink:
    """One byte stream to one device (module notes).

    Parameters
    ----------
    url : str
        ``tcp://HOST[:PORT]`` or anything ``serial.serial_for_url`` opens.
    name : callable
        Returns who the device is, for messages (a driver's name may change once it knows the model).
    default_port : int, optional
        The port of a ``tcp://`` URL without one.
    baudrate : int
        For serial ports (8N1).
    max_reply_bytes : int
        Most bytes held while waiting for one reply.
    poll_s, quiet_s : float
        Longest single blocking read, s; the quiet time that ends a drain, s.

    Raises
    ------
    ValueError
        A malformed ``tcp://`` URL (a local path is checked when it is opened).
    """

    def __init__(self, url: str, name: Callable[[], str], *, default_port: int | None = None, baudrate: int = 115200,
                 max_reply_bytes: int = 1 << 16, poll_s: float = 0.02, quiet_s: float = 0.05) -> None:
        self.url = url
        self._name = name
        self._tcp = parse_tcp_url(url, default_port)
        self._baudrate, self._max_reply, self._poll_s, self._quiet_s = baudrate, max_reply_bytes, poll_s, quiet_s
        self._stream: _TcpStream | _SerialStream | None = None
        self._buffer = bytearray()
        self._lost: str | None = None
        self.dirty = False  #: late bytes of a failed exchange may be pending: drain before the next one

    @property
    def is_open(self) -> bool:
        """True while open (not after :meth:`close` or a lost connection)."""
        return self._stream is not None

    def open(self, timeout_s: float) -> None:
        """Connect (TCP within ``timeout_s``) or open the port; an open link is closed first.

        Raises
        ------
        ValueError
            A URL scheme pyserial does not know, or a path that is not an allowed device path.
        DeviceDisconnected
            Refused, unreachable, or the port cannot be opened.
        """
        self.close()
        self._refuse_path()
        try:
            if self._tcp is not None:
                self._stream = _TcpStream(self._tcp, timeout_s, self._poll_s)
            else:
                self._stream = _SerialStream(self.url, self._baudrate, timeout_s, self._poll_s)
        except ValueError as error:
            raise ValueError(f"{self._name()}: cannot open {self.url!r} ({error}); for sim:// URLs call "
                             "wavestack.simulators.serial_registry.register_serial_simulators() first") from None
        except (serial.SerialException, OSError) as error:
            raise DeviceDisconnected(self._name(), f"cannot open {self.url} ({error})") from error
        self._buffer, self._lost, self.dirty = bytearray(), None, False

    def close(self, *, forget_loss: bool = True) -> None:
        """Close; idempotent. ``forget_loss``: later calls no longer report an earlier loss."""
        stream, self._stream = self._stream, None
        if forget_loss:
            self._lost = None
        if stream is not None:
            try:
                stream.close()
            except (serial.SerialException, OSError) as error:
                logger.debug("%s: error while closing (%s)", self._name(), error)

    def require_open(self) -> None:
        """:class:`DeviceDisconnected` when closed or lost."""
        if self._lost is not None:
            raise DeviceDisconnected(self._name(), f"connection lost earlier ({self._lost}); call open() again")
        if self._stream is None:
            raise DeviceDisconnected(self._name(), "not open; call open() first")

    def exchange(self, data: bytes, complete: Framing[T], deadline: float, *, during: str,
                 fresh: bool = False) -> T:
        """Write ``data`` and read one complete reply before ``deadline``.

        ``fresh``: first discard every byte already received (a device whose replies carry no
        request id, so any earlier byte is stale).

        Raises
        ------
        DeviceTimeout
            The write, or a complete reply, did not finish before the deadline.
        ProtocolError
            From ``complete``, or ``max_reply_bytes`` received without a complete reply.
        DeviceDisconnected
            The connection failed, or was lost earlier.
        """
        self.send(data, deadline, during=during, fresh=fresh)
        return self.receive(complete, deadline, during=during)

    def send(self, data: bytes, deadline: float, *, during: str, fresh: bool = False) -> None:
        """Write ``data`` before ``deadline`` (see :meth:`exchange`)."""
        stream = self._require_stream()
        if fresh:
            self._discard_pending(stream)
        self._io(during, lambda: stream.write(data, deadline))

    def receive(self, complete: Framing[T], deadline: float, *, during: str) -> T:
        """Read until ``complete`` finds a reply, before ``deadline`` (see :meth:`exchange`)."""
        stream = self._require_stream()
        try:
            while True:
                reply, rest = complete(self._buffer)
                if reply is not None:
                    self._buffer = bytearray(rest)
                    return reply
                if len(self._buffer) >= self._max_reply:
                    raise ProtocolError(self._name(), f"{len(self._buffer)} bytes without a complete reply during "
                                        f"{during}; expected a reply of at most {self._max_reply} bytes")
                if time.monotonic() >= deadline:
                    raise DeviceTimeout(self._name(), f"no complete reply during {during} before the deadline "
                                        f"(got {bytes(self._buffer[-60:])!r})")
                self._buffer += self._io(during, lambda: stream.read(min(_CHUNK, self._max_reply - len(self._buffer))))
        except (DeviceTimeout, ProtocolError):
            self.dirty = True
            raise

    def drain(self, deadline: float) -> int:
        """Discard input until the line has been quiet for ``quiet_s`` (or the deadline); the bytes dropped."""
        stream = self._require_stream()
        dropped = len(self._buffer)
        self._buffer = bytearray()
        quiet_since = time.monotonic()
        while time.monotonic() - quiet_since < self._quiet_s and time.monotonic() < deadline:
            chunk = self._io("draining", lambda: stream.read(_CHUNK))
            if chunk:
                dropped += len(chunk)
                quiet_since = time.monotonic()
        self.dirty = False
        logger.debug("%s: drained %d stale bytes", self._name(), dropped)
        return dropped

    # ----------------------------------------------------------------------------- internals
    def _refuse_path(self) -> None:
        refusal = check_device_path(self.url) if "://" not in self.url else None
        if refusal is not None:
            raise ValueError(f"{self._name()}: refusing to open {self.url!r}: {refusal}")

    def _require_stream(self) -> _TcpStream | _SerialStream:
        self.require_open()
        assert self._stream is not None
        return self._stream

    def _discard_pending(self, stream: _TcpStream | _SerialStream) -> None:
        """Drop what was received and what is waiting now, at most ``max_reply_bytes`` of it."""
        dropped, self._buffer = len(self._buffer), bytearray()
        while dropped < self._max_reply and (chunk := self._io("discarding stale input", lambda: stream.read(_CHUNK, wait=False))):
            dropped += len(chunk)

    def _io(self, during: str, action: Callable[[], T]) -> T:
        """Run one I/O call: a write timeout -> DeviceTimeout, any other failure -> DeviceDisconnected (sticky)."""
        try:
            return action()
        except DeviceError:
            raise
        except serial.SerialTimeoutException as error:
            self.dirty = True
            raise DeviceTimeout(self._name(), f"{during}: the write did not finish ({error})") from error
        except (serial.SerialException, OSError) as error:
            self._lost = f"{type(error).__name__}: {error}"
            self.close(forget_loss=False)
            raise DeviceDisconnected(self._name(), f"connection failed during {during} ({error})") from error


class LinkedDevice:
    """Open, close and ``with`` of a driver that has one :class:`ByteLink` (module notes).

    A subclass sets ``_link``, ``_lock`` (a ``threading.RLock``) and ``timeout_s``, and defines
    ``name`` and ``_handshake(timeout_s)``, which reads what the driver needs once open.
    """

    _link: ByteLink
    _lock: threading.RLock
    timeout_s: float

    @property
    def name(self) -> str:  # pragma: no cover - every driver names itself
        raise NotImplementedError

    @property
    def is_open(self) -> bool:
        """True between a successful :meth:`open` and :meth:`close` or a lost connection."""
        return self._link.is_open

    def open(self, timeout_s: float | None = None) -> None:
        """Open the link and run the handshake within ``timeout_s`` per exchange (default: the driver's).

        Raises
        ------
        ValueError
            A URL that cannot be opened (unknown scheme, a path outside the device allow-list).
        DeviceDisconnected
            The link cannot be opened.
        DeviceTimeout, ProtocolError
            The handshake failed; the link is closed again.
        """
        timeout = self.timeout_s if timeout_s is None else timeout_s
        with self._lock:
            if self._link.is_open:
                return
            self._link.open(timeout)
            try:
                self._handshake(timeout)
            except BaseException:
                self._link.close(forget_loss=False)
                raise

    def close(self) -> None:
        """Close the link; idempotent. The device's outputs stay where they are."""
        with self._lock:
            self._link.close()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _handshake(self, timeout_s: float) -> None:  # pragma: no cover - every driver has one
        raise NotImplementedError
