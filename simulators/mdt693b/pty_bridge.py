"""Serve a simulated controller on a pseudo-terminal, so any serial program can open it by path.

:class:`PtyBridge` opens a pty pair, puts the slave in raw mode and runs one (non-daemon) thread
that reads what the host writes to the slave path from the master side, passes it through
``device.feed`` and writes the answer back, honouring the device's delivery plan (split replies).
The driver opens :attr:`PtyBridge.port_path` with ``serial.serial_for_url`` exactly like
``/dev/ttyUSB0``, so the real termios code path runs.

The bridge keeps its own slave descriptor open for its whole life: on Linux a master reads EIO
whenever no slave is open, and the path disappears when the last slave closes. Setting the
device's ``unplugged`` fault closes the master, as pulling the cable would: the host's next read or
write fails. ``close()`` stops and joins the thread and closes both descriptors.
"""

from __future__ import annotations

import logging
import os
import select
import threading
import tty
from types import TracebackType

from wavestack.simulators.mdt693b.device import MDT693BDevice

logger = logging.getLogger(__name__)

_POLL_S = 0.02  # how often the serving thread looks at the stop flag and the unplugged switch


class PtyBridge:
    """A simulated controller behind a pseudo-terminal.

    Parameters
    ----------
    device
        The device model to serve.

    Attributes
    ----------
    port_path
        Path of the slave side (e.g. ``/dev/pts/5``), to give to a serial driver.
    device
        The device model.
    """

    def __init__(self, device: MDT693BDevice) -> None:
        self.device = device
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
        self._thread = threading.Thread(target=self._serve, name=f"pty-bridge {self.port_path}", daemon=False)
        self._thread.start()
        logger.info("simulated %s on %s", device.personality.model, self.port_path)

    @property
    def unplugged(self) -> bool:
        """True once the master side has been closed by the unplugged fault."""
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

    def __enter__(self) -> PtyBridge:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            master = self._master
            if master is None:  # unplugged: nothing left to serve until close()
                self._stop.wait(_POLL_S)
                continue
            if self.device.faults.unplugged:
                self._unplug()
                continue
            try:
                readable, _, _ = select.select([master], [], [], _POLL_S)
                if not readable:
                    continue
                data = os.read(master, 4096)
            except OSError as error:
                logger.warning("pty bridge %s: read failed (%s); unplugging", self.port_path, error)
                self._unplug()
                continue
            reply = self.device.feed(data)
            for delay, chunk in self.device.delivery_plan(reply):
                if delay and self._stop.wait(delay):
                    return
                if not self._write(chunk):
                    break

    def _write(self, chunk: bytes) -> bool:
        master = self._master
        if master is None or self.device.faults.unplugged:
            return False
        view = memoryview(chunk)
        try:
            while view:
                written = os.write(master, view)
                view = view[written:]
        except OSError as error:
            logger.warning("pty bridge %s: write failed (%s)", self.port_path, error)
            return False
        return True

    def _unplug(self) -> None:
        with self._fd_lock:
            if self._master is not None:
                os.close(self._master)
                self._master = None
                logger.info("pty bridge %s: unplugged", self.port_path)
