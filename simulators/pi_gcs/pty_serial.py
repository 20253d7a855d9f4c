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

from wavestack.simulators.pi_gcs.controller import GcsController
from wavestack.simulators.pi_gcs.framing import LineAssembler
from wavestack.simulators.pty_port import PtyServer

__all__ = ["GcsPtyBridge"]

_log = logging.getLogger(__name__)
_POLL_S = 0.02  # how often the serving thread looks at the stop flag


class GcsPtyBridge(PtyServer):
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
        self._assembler = LineAssembler()
        super().__init__("GCS pty", daemon=True)
        _log.info("simulated GCS controller on %s", self.port_path)

    def _serve(self) -> None:
        while not self._stop.is_set():
            data = self._port.read(_POLL_S)
            if data is None:  # unplugged: nothing left to serve until close()
                self._stop.wait(_POLL_S)
                continue
            for event in self._assembler.feed(data):
                delivery = self.controller.handle(event)
                for delay_s, chunk in delivery.pieces:
                    if delay_s and self._stop.wait(delay_s):
                        return
                    self._port.write(chunk)
                if delivery.close:
                    self._port.unplug()
                    break
