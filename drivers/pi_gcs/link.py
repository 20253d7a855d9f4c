"""The byte link to one PI GCS controller: TCP (port 50000 by default) or anything pyserial opens.

:class:`GcsLink` *has* either a TCP socket (``tcp://HOST[:PORT]``; C-887 controllers listen on
port 50000, MS204E [1]_) or a ``serial.serial_for_url`` port (RS-232 ``/dev/ttyUSB0``, ``COM3``,
a pseudo-terminal, ``socket://``, ``sim://``) at 115200 8N1, the C-887's default RS-232 setting
[1]_. It knows framing only: write bytes, read until a reply is complete
(:func:`~wavestack.drivers.pi_gcs.protocol.reply_end`) or the deadline passes, turn I/O failures
into typed errors. After a timeout or a garbled reply the link is *dirty*: late bytes of that
reply could be taken for the next one, so the next exchange first drains the input until it has
been quiet for a moment. A lost connection stays lost until :meth:`open` is called again.
The caller serialises access (the driver's lock).

References
----------
.. [1] Physik Instrumente, MS204E, "C-887 Hexapod Controller User Manual" (interfaces: TCP/IP port
   50000, RS-232 115200 baud).
"""

from __future__ import annotations

import logging
import re
import socket
import time
from collections.abc import Callable

import serial

from wavestack.drivers.device_path import check_device_path
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, ProtocolError
from wavestack.drivers.pi_gcs.protocol import split_reply

__all__ = ["DEFAULT_PORT", "GcsLink", "parse_tcp_url"]

logger = logging.getLogger(__name__)

DEFAULT_PORT = 50000
_POLL_S = 0.02  # longest single blocking read: how often a waiting read checks its deadline
_QUIET_S = 0.05  # draining: the input counts as quiet after this long without a byte
_MAX_REPLY = 1 << 16  # a reply longer than this is garbage (a GCS reply is a few hundred bytes)
_TCP_URL = re.compile(r"^tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[^:/\s\[\]]+)(:(?P<port>\d{1,5}))?/?$")


def parse_tcp_url(url: str) -> tuple[str, int] | None:
    """``(host, port)`` of a ``tcp://HOST[:PORT]`` URL (port 50000 when absent), None for other URLs.

    Examples
    --------
    >>> parse_tcp_url("tcp://192.168.0.10"), parse_tcp_url("tcp://127.0.0.1:5555"), parse_tcp_url("/dev/ttyS0")
    (('192.168.0.10', 50000), ('127.0.0.1', 5555), None)
    """
    if not url.startswith("tcp://"):
        return None
    match = _TCP_URL.fullmatch(url)
    if match is None or not 0 < int(match.group("port") or DEFAULT_PORT) < 65536:
        raise ValueError(f"expected tcp://HOST[:PORT] with a port 1..65535, got {url!r}")
    return match.group("host").strip("[]"), int(match.group("port") or DEFAULT_PORT)


class GcsLink:
    """Framed exchanges with one controller over TCP or a pyserial URL (see the module notes).

    Parameters
    ----------
    url
        ``tcp://HOST[:PORT]`` or anything ``serial.serial_for_url`` opens.
    name
        Returns who the controller is, for messages.
    """

    def __init__(self, url: str, name: Callable[[], str]) -> None:
        self.url = url
        self._name = name
        self._tcp = parse_tcp_url(url)
        if self._tcp is None and "://" not in url:
            refusal = check_device_path(url)
            if refusal is not None:
                raise ValueError(f"refusing to open {url!r}: {refusal}")
        self._sock: socket.socket | None = None
        self._port: serial.SerialBase | None = None
        self._buffer = b""
        self._dirty = False
        self._lost: str | None = None

    @property
    def is_open(self) -> bool:
        """True while connected (not after :meth:`close` or a lost connection)."""
        return self._sock is not None or self._port is not None

    def open(self, timeout_s: float) -> None:
        """Connect (TCP, within ``timeout_s``) or open the serial port.

        Raises
        ------
        ValueError
            A URL pyserial does not know.
        DeviceDisconnected
            Connection refused, unreachable, or the port cannot be opened.
        """
        self.close()
        try:
            if self._tcp is not None:
                sock = socket.create_connection(self._tcp, timeout=timeout_s)
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                sock.settimeout(_POLL_S)
                self._sock = sock
            else:
                self._port = serial.serial_for_url(self.url, baudrate=115200, bytesize=8, parity="N", stopbits=1,
                                                   timeout=_POLL_S, write_timeout=timeout_s)
        except ValueError as error:
            raise ValueError(f"{self._name()}: cannot open {self.url!r} ({error})") from None
        except (serial.SerialException, OSError) as error:
            raise DeviceDisconnected(self._name(), f"cannot connect to {self.url} ({error}); expected a PI GCS "
                                     "controller listening there") from error
        self._buffer, self._dirty, self._lost = b"", False, None

    def close(self) -> None:
        """Close the connection; idempotent."""
        sock, port, self._sock, self._port = self._sock, self._port, None, None
        try:
            if sock is not None:
                sock.close()
            if port is not None:
                port.close()
        except (serial.SerialException, OSError) as error:
            logger.debug("%s: error while closing (%s)", self._name(), error)

    def send(self, data: bytes, deadline: float) -> None:
        """Write ``data`` (one or more commands, or a single-byte command); drain first if dirty."""
        self._require_open()
        if self._dirty:
            self._drain(deadline)
        self._io("writing", lambda: self._write(data))

    def read_reply(self, deadline: float, during: str) -> list[str]:
        """Read one complete reply (its lines) before ``deadline``; marks the link dirty on failure.

        Raises
        ------
        DeviceTimeout
            No complete reply before the deadline.
        ProtocolError
            The reply is not GCS text, or too long.
        DeviceDisconnected
            The connection was lost.
        """
        return self._read_until(lambda buf: split_reply(buf, device=self._name()), deadline, during)

    def read_raw_reply(self, deadline: float, during: str) -> bytes:
        """Read one reply up to its LF without decoding it (the ``#7`` answer is a byte above ASCII)."""
        def take(buf: bytes) -> tuple[bytes | None, bytes]:
            end = buf.find(b"\n")
            return (None, buf) if end < 0 else (buf[:end + 1], buf[end + 1:])
        return self._read_until(take, deadline, during)

    # ----------------------------------------------------------------------------- internals
    def _read_until(self, take, deadline: float, during: str):  # type: ignore[no-untyped-def]
        self._require_open()
        try:
            while True:
                reply, rest = take(self._buffer)
                if reply is not None:
                    self._buffer = rest
                    return reply
                if len(self._buffer) > _MAX_REPLY:
                    raise ProtocolError(self._name(), f"{len(self._buffer)} bytes without a complete reply "
                                        f"during {during}; expected a GCS reply ending in LF")
                if time.monotonic() >= deadline:
                    raise DeviceTimeout(self._name(), f"no complete reply during {during} before the deadline "
                                        f"(expected a line ending in LF, got {self._buffer[-60:]!r})")
                self._buffer += self._io(during, self._read_some)
        except (DeviceTimeout, ProtocolError):
            self._dirty = True
            raise

    def _drain(self, deadline: float) -> None:
        """Discard pending and late input until the line has been quiet for ``_QUIET_S``."""
        dropped = len(self._buffer)
        self._buffer = b""
        quiet_since = time.monotonic()
        while time.monotonic() - quiet_since < _QUIET_S and time.monotonic() < deadline:
            chunk = self._io("draining", self._read_some)
            if chunk:
                dropped += len(chunk)
                quiet_since = time.monotonic()
        self._dirty = False
        logger.debug("%s: drained %d stale bytes", self._name(), dropped)

    def _write(self, data: bytes) -> None:
        if self._sock is not None:
            self._sock.sendall(data)
        elif self._port is not None:
            self._port.write(data)
            self._port.flush()

    def _read_some(self) -> bytes:
        if self._sock is not None:
            try:
                chunk = self._sock.recv(4096)
            except TimeoutError:
                return b""
            if not chunk:
                raise ConnectionResetError("connection closed by the controller")
            return chunk
        assert self._port is not None
        return bytes(self._port.read(max(1, self._port.in_waiting)))

    def _require_open(self) -> None:
        if self._lost is not None:
            raise DeviceDisconnected(self._name(), f"connection lost earlier ({self._lost}); call open() again")
        if not self.is_open:
            raise DeviceDisconnected(self._name(), "not connected; call open() first")

    def _io(self, during: str, action):  # type: ignore[no-untyped-def]
        """Run one I/O ``action``; failures become DeviceTimeout (write timeout) or DeviceDisconnected (sticky)."""
        try:
            return action()
        except DeviceError:
            raise
        except serial.SerialTimeoutException as error:
            self._dirty = True
            raise DeviceTimeout(self._name(), f"{during} did not finish ({error})") from error
        except (serial.SerialException, OSError) as error:
            self._lost = f"{type(error).__name__}: {error}"
            self.close()
            raise DeviceDisconnected(self._name(), f"connection failed during {during} ({error})") from error
