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

from wavestack.simulators.mdt693b.device import MDT693BDevice
from wavestack.simulators.pty_port import PtyServer

logger = logging.getLogger(__name__)

_POLL_S = 0.02  # how often the serving thread looks at the stop flag and the unplugged switch


class PtyBridge(PtyServer):
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
        super().__init__("pty bridge", daemon=False)
        logger.info("simulated %s on %s", device.personality.model, self.port_path)

    def _serve(self) -> None:
        while not self._stop.is_set():
            if self.device.faults.unplugged:
                self._port.unplug()
            data = self._port.read(_POLL_S)
            if data is None:  # unplugged: nothing left to serve until close()
                self._stop.wait(_POLL_S)
                continue
            if not data:
                continue
            reply = self.device.feed(data)
            for delay, chunk in self.device.delivery_plan(reply):
                if delay and self._stop.wait(delay):
                    return
                if self.device.faults.unplugged or not self._port.write(chunk):
                    break
