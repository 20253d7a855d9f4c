"""The simulated GCS controller on a pseudo-terminal: the RS-232 port of a C-887, for any serial program.

:class:`GcsPtyBridge` opens a pty pair, puts the slave in raw mode and runs one thread that reads
what the host writes to :attr:`GcsPtyBridge.port_path`, cuts it into GCS events
(:class:`~wavestack.simulators.pi_gcs.framing.LineAssembler`) and writes the controller's answers
back, honouring split answers. A driver opens the path with ``serial.serial_for_url`` exactly like
``/dev/ttyUSB0`` (baud rate and framing mean nothing on a pty). A dropped-connection fault closes
the master side, as pulling the cable would: the host's next read or write fails. The bridge keeps
its own slave descriptor open (on Linux a master reads EIO while no slave is open).
"""

from __future__ import annotations

import logging
import os
import select
import threading
import tty
from types import TracebackType

from wavestack.simulators.pi_gcs.controller import GcsController
from wavestack.simulators.pi_gcs.framing import LineAssembler

__all__ = ["GcsPtyBridge"]

_log = logging.getLogger(__name__)
_POLL_S = 0.02  # how often the serving thread looks at the stop flag


class GcsPtyBridge:
    """A simulated GCS controller behind a pseudo-terminal (see the module docstring).

    Parameters
    ----------
    controller
        The controller to serve (its faults and state stay reachable through it).

    Examples
    --------
    >>> import serial
    >>> from wavestack.simulators.pi_gcs import HexapodSimSettings
    >>> with GcsPtyBridge(GcsController(HexapodSimSettings())) as bridge:
    ...     port = serial.serial_for_url(bridge.port_path, timeout=5.0)
    ...     port.write(b"CSV?\\n")
    ...     port.readline()
    ...     port.close()
    5
    b'2.0\\n'
    """

    def __init__(self, controller: GcsController) -> None:
        self.controller = controller
        master, slave = os.openpty()
        try:
            tty.setraw(slave)
            self.port_path = os.ttyname(slave)
        except BaseException:
            os.close(master)
            os.close(slave)
            raise
        self._master: int | None = master
        self._slave: int | None = slave
        self._fd_lock = threading.Lock()
        self._stop = threading.Event()
        self._assembler = LineAssembler()
        self._thread = threading.Thread(target=self._serve, name=f"gcs-pty {self.port_path}", daemon=True)
        self._thread.start()
        _log.info("simulated GCS controller on %s", self.port_path)

    @property
    def unplugged(self) -> bool:
        """True once a dropped-connection fault closed the master side."""
        with self._fd_lock:
            return self._master is None and not self._stop.is_set()

    def close(self) -> None:
        """Stop serving, join the thread and close both descriptors; idempotent."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join()
        with self._fd_lock:
            for fd in (self._master, self._slave):
                if fd is not None:
                    os.close(fd)
            self._master = self._slave = None

    def __enter__(self) -> GcsPtyBridge:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            master = self._master
            if master is None:
                self._stop.wait(_POLL_S)
                continue
            try:
                readable, _, _ = select.select([master], [], [], _POLL_S)
                data = os.read(master, 4096) if readable else b""
            except OSError as error:
                _log.warning("GCS pty %s: read failed (%s); unplugging", self.port_path, error)
                self._unplug()
                continue
            for event in self._assembler.feed(data):
                delivery = self.controller.handle(event)
                for delay_s, chunk in delivery.pieces:
                    if delay_s and self._stop.wait(delay_s):
                        return
                    self._write(chunk)
                if delivery.close:
                    self._unplug()
                    break

    def _write(self, chunk: bytes) -> None:
        master = self._master
        if master is None:
            return
        view = memoryview(chunk)
        try:
            while view:
                view = view[os.write(master, view):]
        except OSError as error:
            _log.warning("GCS pty %s: write failed (%s)", self.port_path, error)

    def _unplug(self) -> None:
        with self._fd_lock:
            if self._master is not None:
                os.close(self._master)
                self._master = None
                _log.info("GCS pty %s: unplugged", self.port_path)
