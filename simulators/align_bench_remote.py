"""The alignment bench as a remote user's devices: served on their real transports, the telescope coupled inside.

:class:`RemoteAlignBench` serves, from one process, what a real alignment bench puts on the
network and on the host's buses: the PI hexapod and the PI field stage (GCS 2.0 over TCP, the
:class:`~wavestack.simulators.align_bench.AlignmentBench`'s two simulators), the interferometer's
USB3 Vision camera (its USB bus served over TCP, :class:`~wavestack.simulators.usb_tcp.UsbTcpServer`:
a camera is a USB device, which no other process can reach otherwise) and its MDT693B piezo (on
a pseudo-terminal, as a serial port, or on TCP as behind a serial device server,
:class:`SerialTcpBridge`, which a host opens as ``socket://HOST:PORT``). The as-built telescope is coupled inside: a follower thread
re-renders the wavefront whenever the hexapod's or the field stage's position changes (and at
least every ``refresh_s``) and puts it on the station optic's surface, less the tilt the
reference takes out as an operator does (:class:`~wavestack.simulators.align_bench.SurfaceCoupling`);
the tilt is *not* handed to the host, which sees only the camera's frames. The camera therefore
shows the pose the hexapod simulator holds, one render (a few ms) after it changed: the host's
settle time covers that, as it covers a real platform's ringing.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from contextlib import ExitStack

from wavestack.simulators.align_bench import AlignmentBench, SurfaceCoupling
from wavestack.simulators.bench import SimulatedInterferometer
from wavestack.simulators.mdt693b import MDT693BDevice, PtyBridge
from wavestack.simulators.usb_tcp import UsbTcpServer

__all__ = ["RemoteAlignBench", "SerialTcpBridge"]

logger = logging.getLogger(__name__)

_POLL_S = 0.005  # how often the follower looks at the two positions
_BRIDGE_POLL_S = 0.05  # how often the serial bridge looks at its stop flag


class RemoteAlignBench:
    """Serve the bench's four devices with the telescope coupled (module notes); a context manager.

    Parameters
    ----------
    bench : AlignmentBench
        The controllers (with their host and ports) and the as-built telescope.
    interferometer : SimulatedInterferometer
        The station's camera, optic and piezo (the optic's surface on the TMA's camera grid).
    piezo : MDT693BDevice or None
        The piezo wired to the camera, served on a pseudo-terminal.
    coupling : SurfaceCoupling
        Bench -> optic surface.
    camera_port : int
        TCP port of the camera's USB bus (0: a free one), on the bench's host.
    piezo_port : int or None
        Serve the piezo on this TCP port (0: a free one) instead of a pseudo-terminal.
    refresh_s : float
        Longest time between two renders when nothing moves.

    Example
    -------
    ``wavestack sim align-bench`` builds one from an alignment TOML and prints where each device is.
    """

    def __init__(self, bench: AlignmentBench, interferometer: SimulatedInterferometer, piezo: MDT693BDevice | None,
                 coupling: SurfaceCoupling, *, host: str = "127.0.0.1", camera_port: int = 0,
                 piezo_port: int | None = None, refresh_s: float = 1.0) -> None:
        self.bench, self.interferometer, self._piezo, self._coupling = bench, interferometer, piezo, coupling
        self.usb = UsbTcpServer(interferometer.backend, host=host, port=camera_port)
        self.piezo_pty: PtyBridge | None = None
        self.piezo_tcp: SerialTcpBridge | None = None
        self._host, self._piezo_port = host, piezo_port
        self._refresh_s = float(refresh_s)
        self._stack = ExitStack()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.renders = 0

    def __enter__(self) -> RemoteAlignBench:
        with ExitStack() as stack:
            stack.enter_context(self.bench)
            self._coupling.refresh()  # the camera shows the telescope before anyone connects
            self._thread = threading.Thread(target=self._follow, name="align-bench-follower")
            self._thread.start()
            stack.callback(self._end_follower)
            stack.enter_context(self.usb)
            if self._piezo is not None and self._piezo_port is None:
                self.piezo_pty = stack.enter_context(PtyBridge(self._piezo))
            elif self._piezo is not None:
                self.piezo_tcp = stack.enter_context(SerialTcpBridge(self._piezo, host=self._host,
                                                                     port=self._piezo_port))
            self._stack = stack.pop_all()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def _end_follower(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def lose_camera(self) -> None:
        """Fault switch: drop the camera's USB connections (to the host, the camera left the bus)."""
        self.usb.disconnect_clients()

    def _positions(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        return tuple(self.bench.hexapod.pose.values), tuple(self.bench.field_stage.pose.values)

    def _follow(self) -> None:
        last = self._positions()
        idle = 0.0
        while not self._stop.wait(_POLL_S):
            now = self._positions()
            idle += _POLL_S
            if now == last and idle < self._refresh_s:
                continue
            try:
                self._coupling.refresh()
                self.renders += 1
            except Exception as error:  # a render failure must not end the bench; log and keep following
                logger.error("align bench: render failed: %s", error, exc_info=True)
            last, idle = now, 0.0


class SerialTcpBridge:
    """A serial device on raw TCP, as a serial device server ("TCP server" mode) puts one on a network.

    One client at a time, as a device server serves its port; bytes in are fed to the device, its
    replies go out as its delivery plan schedules them (:class:`~wavestack.simulators.mdt693b.PtyBridge`
    does the same on a pty). A client that sends nothing for ``idle_timeout_s`` is disconnected (a
    device server's inactivity timeout), so a silent peer cannot keep the port from the station
    for longer; the station's driver reconnects after it. A context manager; :meth:`close` ends the
    thread and closes every socket.
    """

    def __init__(self, device: MDT693BDevice, *, host: str = "127.0.0.1", port: int = 0,
                 idle_timeout_s: float = 30.0) -> None:
        self.device = device
        self.idle_timeout_s = idle_timeout_s
        self.idle_disconnects = 0  #: clients dropped for silence
        self._listener = socket.create_server((host, port), backlog=1)
        self._listener.settimeout(_BRIDGE_POLL_S)
        self.port = self._listener.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name=f"serial-tcp-{self.port}")

    def __enter__(self) -> SerialTcpBridge:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        self._listener.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            with client:
                client.settimeout(_BRIDGE_POLL_S)
                self._talk(client)

    def _talk(self, client: socket.socket) -> None:
        heard = time.monotonic()
        while not self._stop.is_set():
            try:
                data = client.recv(4096)
            except TimeoutError:
                if time.monotonic() - heard > self.idle_timeout_s:
                    logger.warning("serial bridge %d: a client silent for %.0f s was disconnected", self.port,
                                   self.idle_timeout_s)
                    self.idle_disconnects += 1
                    return
                continue
            except OSError:
                return
            if not data:
                return
            heard = time.monotonic()
            for delay, chunk in self.device.delivery_plan(self.device.feed(data)):
                if delay and self._stop.wait(delay):
                    return
                try:
                    client.sendall(chunk)
                except OSError:
                    return
