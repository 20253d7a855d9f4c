"""The master side of a pseudo-terminal pair, as the simulators' serial ports use it.

A simulated serial instrument serves its controller on a pty: the host opens :attr:`PtyPort.path`
(the slave side) with ``serial.serial_for_url`` exactly like ``/dev/ttyUSB0``, so the real termios
code runs; the simulator reads and writes the master side. The port keeps its own slave
descriptor open for its whole life: on Linux a master reads EIO whenever no slave is open, and the
path disappears when the last slave closes. :meth:`unplug` closes the master, as pulling the cable
would: the host's next read or write fails.
"""

from __future__ import annotations

import logging
import os
import select
import threading
import tty
from types import TracebackType
from typing import Self

__all__ = ["PtyPort", "PtyServer"]

_log = logging.getLogger(__name__)


class PtyPort:
    """A pty pair in raw mode; the simulator's end is the master.

    Parameters
    ----------
    label : str
        Names the port in log lines (e.g. ``"GCS pty"``).

    Attributes
    ----------
    path : str
        The slave side (e.g. ``/dev/pts/5``), to give to a serial driver.

    Examples
    --------
    >>> import serial
    >>> port = PtyPort("example")
    >>> host = serial.serial_for_url(port.path, timeout=1.0)
    >>> _ = host.write(b"ping")
    >>> port.read(1.0)
    b'ping'
    >>> port.write(b"pong"), host.read(4)
    (True, b'pong')
    >>> host.close(); port.close()
    """

    def __init__(self, label: str) -> None:
        self._label = label
        master, slave = os.openpty()
        try:
            tty.setraw(slave)
            self.path = os.ttyname(slave)
        except BaseException:
            os.close(master)
            os.close(slave)
            raise
        self._master: int | None = master
        self._slave: int | None = slave
        self._lock = threading.Lock()

    @property
    def unplugged(self) -> bool:
        """True once the master side is closed (unplugged or closed)."""
        with self._lock:
            return self._master is None

    def read(self, timeout_s: float) -> bytes | None:
        """What the host wrote within ``timeout_s`` (maybe ``b""``); None once unplugged (a failed read unplugs)."""
        master = self._master
        if master is None:
            return None
        try:
            readable, _, _ = select.select([master], [], [], timeout_s)
            return os.read(master, 4096) if readable else b""
        except OSError as error:
            _log.warning("%s %s: read failed (%s); unplugging", self._label, self.path, error)
            self.unplug()
            return None

    def write(self, chunk: bytes) -> bool:
        """Write all of ``chunk`` to the host; False if unplugged or the write failed."""
        master = self._master
        if master is None:
            return False
        view = memoryview(chunk)
        try:
            while view:
                view = view[os.write(master, view):]
        except OSError as error:
            _log.warning("%s %s: write failed (%s)", self._label, self.path, error)
            return False
        return True

    def unplug(self) -> None:
        """Close the master side (the cable pulled); idempotent."""
        with self._lock:
            if self._master is not None:
                os.close(self._master)
                self._master = None
                _log.info("%s %s: unplugged", self._label, self.path)

    def close(self) -> None:
        """Close both sides; idempotent."""
        with self._lock:
            for fd in (self._master, self._slave):
                if fd is not None:
                    os.close(fd)
            self._master = self._slave = None


class PtyServer:
    """A :class:`PtyPort` served by one thread running the subclass's ``_serve`` until :meth:`close`.

    Subclasses set what they need, then call ``super().__init__``, which starts the thread.
    ``_serve`` loops while ``self._stop`` is not set, reading and writing ``self._port``.

    Parameters
    ----------
    label : str
        Names the port and the thread.
    daemon : bool
        Whether the serving thread is a daemon thread.
    """

    def __init__(self, label: str, *, daemon: bool) -> None:
        self._port = PtyPort(label)
        self.port_path = self._port.path
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name=f"{label} {self.port_path}", daemon=daemon)
        self._thread.start()

    @property
    def unplugged(self) -> bool:
        """True once the master side was closed by a fault (not by :meth:`close`)."""
        return self._port.unplugged and not self._stop.is_set()

    def close(self) -> None:
        """Stop serving, join the thread and close both descriptors; idempotent."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join()
        self._port.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _serve(self) -> None:  # pragma: no cover - every subclass defines it
        raise NotImplementedError
