"""GigE Vision camera: GVCP control with the heartbeat, the GenICam node map, the GVSP stream.

:class:`GigECamera` *has* a :class:`~wavestack.drivers.gige.control.ControlChannel`. Opening it
takes the control privilege (CCP), reads the bootstrap registers and the GenICam file the first URL
names, and starts the heartbeat: a thread that reads a register every third of the camera's
heartbeat timeout, which keeps the privilege and notices a camera that stopped answering (the ring
is then closed with ``DeviceDisconnected``, so a consumer never waits on a dead camera). Frames
arrive through :meth:`start` / :meth:`read_frame` / :meth:`stop`, with the same
:class:`~wavestack.drivers.frames.Frame`, ring and counters as the USB3 Vision driver.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from types import TracebackType

from wavestack.drivers.errors import DeviceDisconnected, DeviceError, ProtocolError, renewed
from wavestack.drivers.frames import Frame
from wavestack.drivers.genicam import NodeMap
from wavestack.drivers.genicam.camera_features import CameraFeatures, unlock_quietly
from wavestack.drivers.genicam.camera_verbs import GenICamCamera
from wavestack.drivers.gige import gvcp
from wavestack.drivers.gige.control import ControlChannel, GvcpPort
from wavestack.drivers.gige.discovery import locate, parse_gige_url
from wavestack.drivers.gige.stream import StreamReceiver
from wavestack.drivers.ring import FrameRing, RingPolicy
from wavestack.drivers.ring_history import RingHistory
from wavestack.drivers.role_thread import Job, RoleThread

logger = logging.getLogger(__name__)

DEFAULT_PACKET_SIZE = 8192  # bytes per GVSP datagram on the wire (IP + UDP + GVSP headers included)
_IP_UDP_GVSP = 20 + 8 + 8
_STATS = ("packets", "bad_packets", "resend_requests", "blocks_dropped", "heartbeat_failures")


@dataclass(frozen=True)
class GigECounters:
    """Frame counters (``acquired == delivered + dropped + pending``) and stream health.

    Attributes
    ----------
    acquired, delivered, dropped, dropped_in_gaps, pending
        As in :class:`wavestack.drivers.ring.RingCounters`, over the camera's life.
    packets, bad_packets
        GVSP packets received, and those refused (malformed, oversized).
    resend_requests
        PACKETRESEND ranges asked for.
    blocks_dropped
        Blocks given up (incomplete after the resend rounds, or damaged); each is also a gap
        counted in ``dropped``.
    heartbeat_failures
        Heartbeats the camera did not acknowledge.
    """

    acquired: int
    delivered: int
    dropped: int
    dropped_in_gaps: int
    pending: int
    packets: int
    bad_packets: int
    resend_requests: int
    blocks_dropped: int
    heartbeat_failures: int


@dataclass(frozen=True)
class _Link:
    channel: ControlChannel
    features: CameraFeatures
    heartbeat_s: float


class GigECamera(GenICamCamera):
    """A GigE Vision camera (see the module description). Build it with :meth:`open`.

    Example
    -------
    ::

        with GigECamera.open("gige://192.168.10.20", timeout_s=2.0) as camera:
            camera.set_pixel_format("Mono12", timeout_s=1.0)
            camera.start()
            frame = camera.read_frame(timeout_s=1.0)
    """

    def __init__(self, url: str, *, timeout_s: float, ring_capacity: int, ring_policy: RingPolicy,
                 packet_size: int) -> None:
        self._url = parse_gige_url(url)
        if not 576 <= packet_size <= 9000:
            raise ValueError(f"packet_size {packet_size}: expected 576..9000 bytes")
        self._timeout_s = timeout_s
        self._deadline(None)  # checks the timeout before any I/O
        self._packet_size = packet_size
        self._name = f"GigE camera {url[len('gige://'):]}"
        self._ring: FrameRing[Frame] = FrameRing(ring_capacity, ring_policy, name=self._name)
        self._history = RingHistory()
        self._stats = dict.fromkeys(_STATS, 0)
        self._state_lock = threading.Lock()
        self._link: _Link | None = None
        self._lost: DeviceDisconnected | None = None
        self._closed = False
        self._acquiring = False
        self._receiver: StreamReceiver | None = None
        self._stream_role: RoleThread | None = None
        self._heartbeat_role = RoleThread(f"gige-heartbeat {self._name}", daemon=True)
        self._heartbeat: Job | None = None
        self._beating = threading.Event()

    # ----------------------------------------------------------------------------------- opening
    @classmethod
    def open(cls, url: str, *, timeout_s: float, ring_capacity: int = 4,
             ring_policy: RingPolicy = RingPolicy.NEWEST_ONLY, packet_size: int = DEFAULT_PACKET_SIZE) -> GigECamera:
        """Find the camera, take control, read its bootstrap registers and GenICam file, start the heartbeat.

        Parameters
        ----------
        url
            ``gige://ADDRESS[:PORT]`` or ``gige://SERIAL[?via=HOST[:PORT]]``.
        timeout_s
            Longest time for the opening sequence, s; also the default for feature calls.
        ring_capacity, ring_policy
            The frame ring between the stream thread and :meth:`read_frame`.
        packet_size
            GVSP packet size to ask for, bytes (576..9000; 8192 needs jumbo frames, as loopback has).

        Raises
        ------
        ValueError
            A bad URL, timeout or packet size (before any I/O).
        DeviceDisconnected
            No camera at the address, or none with the serial answered DISCOVERY.
        DeviceTimeout, ProtocolError
            The camera did not answer in time, refused control (another host holds it), or answered
            outside the protocol.
        """
        camera = cls(url, timeout_s=timeout_s, ring_capacity=ring_capacity, ring_policy=ring_policy,
                     packet_size=packet_size)
        camera._connect(camera._deadline(None))
        return camera

    def _connect(self, deadline: float) -> None:
        host, port, info = locate(self._url, max(0.05, min(1.0, deadline - time.monotonic())))
        channel = ControlChannel(host, port, self._name)
        try:
            channel.write_register(gvcp.REG_CCP, gvcp.CCP_CONTROL, deadline)
            model = channel.read_memory(gvcp.REG_MODEL, 32, deadline).split(b"\0", 1)[0].decode("ascii", "replace")
            serial = channel.read_memory(gvcp.REG_SERIAL, 16, deadline).split(b"\0", 1)[0].decode("ascii", "replace")
            self._name = f"GigE camera {host}:{port} {model} SN {serial}"
            channel.name = self._name
            if channel.read_register(gvcp.REG_STREAM_CHANNELS, deadline) < 1:
                raise ProtocolError(self._name, "the camera reports no stream channel; expected one")
            heartbeat_ms = channel.read_register(gvcp.REG_HEARTBEAT_TIMEOUT, deadline)
            url = gvcp.parse_first_url(channel.read_memory(gvcp.REG_FIRST_URL, gvcp.URL_LENGTH, deadline), self._name)
            xml = channel.read_memory(url.address, url.length, deadline)
            node_map = NodeMap.from_xml(xml, device=self._name, zipped=url.zipped)
            port_ = GvcpPort(channel)
            node_map.attach(port_)
            features = CameraFeatures(node_map, port_)
            features.require()
        except BaseException:
            channel.close()
            raise
        logger.info("%s: opened (%s)", self._name, info.model if info else f"{host}:{port}")
        self._link = _Link(channel, features, max(0.05, min(heartbeat_ms, 10_000) / 3000))
        self._lost = None
        self._ring = self._history.replace(self._ring, self._name)
        self._beating.set()
        self._heartbeat = self._heartbeat_role.run(self._beat)

    def _beat(self) -> None:
        """Read a register every third of the heartbeat timeout; two misses in a row lose the camera."""
        misses = 0
        while self._beating.is_set():
            link = self._link
            if link is None:
                return
            if not _sleep_while(self._beating, link.heartbeat_s):
                return
            try:
                link.channel.read_register(gvcp.REG_CCP, time.monotonic() + link.heartbeat_s)
                misses = 0
            except DeviceError as error:
                misses += 1
                self._count("heartbeat_failures", 1)
                if misses >= 2 or isinstance(error, DeviceDisconnected):
                    self._mark_lost(DeviceDisconnected(self._name, f"stopped answering GVCP: {error.detail}"))
                    return

    def _mark_lost(self, error: DeviceDisconnected) -> None:
        kept = renewed(error)  # the caller may raise ``error``: its traceback would keep the caller's frames
        with self._state_lock:
            if self._lost is None:
                self._lost = kept
        self._ring.close(kept)

    def _count(self, key: str, amount: int) -> None:
        with self._state_lock:
            self._stats[key] += amount

    def _live(self) -> _Link:
        if self._closed:
            raise DeviceDisconnected(self._name, "camera was closed; open it again")
        if self._lost is not None:
            raise DeviceDisconnected(self._name, "the camera stopped answering; call reopen()")
        if self._link is None:
            raise DeviceDisconnected(self._name, "not connected")
        return self._link

    def _camera_features(self) -> CameraFeatures:
        return self._live().features

    @property
    def connected(self) -> bool:
        """True while the camera answers (not closed, heartbeat not lost)."""
        return not self._closed and self._lost is None and self._link is not None

    def present(self) -> bool:
        """True if the camera answers DISCOVERY (or a register read at its address): a check before :meth:`reopen`."""
        if self._closed:
            return False
        try:
            locate(self._url, 0.2)
        except DeviceDisconnected:
            return False
        return True

    # --------------------------------------------------------------------------------- streaming
    def start(self, timeout_s: float | None = None) -> None:
        """Lock the transport layer, point stream channel 0 at a fresh host socket, AcquisitionStart.

        Frames pending from an earlier acquisition are dropped (counted). Idempotent while running.
        """
        deadline = self._deadline(timeout_s)
        link = self._live()
        if self._receiver is not None:
            return
        features, channel = link.features, link.channel
        max_payload = int(features.get("Width", deadline)) * int(features.get("Height", deadline)) * 2  # type: ignore[arg-type]
        self._stream_role = self._stream_role or RoleThread(f"gige-stream {self._name}", daemon=True)
        if self._ring.closed:
            self._ring = self._history.replace(self._ring, self._name)
        self._ring.discard_pending()
        receiver = StreamReceiver(self._name, channel, self._ring, channel.local_address,
                                  self._packet_size - _IP_UDP_GVSP, max_payload, self._count, self._stream_role)
        try:
            features.lock_transport_layer(deadline)
            channel.write_register(gvcp.REG_SCPS0, gvcp.SCPS_DO_NOT_FRAGMENT | self._packet_size, deadline)
            channel.write_register(gvcp.REG_SCDA0, _ipv4(channel.local_address), deadline)
            channel.write_register(gvcp.REG_SCP0, receiver.port, deadline)
            receiver.start()
            features.execute("AcquisitionStart", deadline)
        except BaseException:
            receiver.join()
            unlock_quietly(features, deadline)
            raise
        self._receiver = receiver
        self._acquiring = True
        logger.info("%s: streaming to port %d, %d-byte packets", self._name, receiver.port, self._packet_size)

    @property
    def reading(self) -> bool:
        """True from :meth:`start` until :meth:`stop` or the camera is lost."""
        return self._receiver is not None and self._receiver.running and self._lost is None

    def counters(self) -> GigECounters:
        """Frame counters over the camera's life and stream health (see :class:`GigECounters`)."""
        c = self._history.with_current(self._ring)
        with self._state_lock:
            stats = dict(self._stats)
        return GigECounters(c.acquired, c.delivered, c.dropped, c.dropped_in_gaps, c.pending, **stats)

    def stop(self, timeout_s: float | None = None) -> None:
        """AcquisitionStop, close the stream socket, clear SCP0 and TLParamsLocked. Idempotent.

        Raises
        ------
        DeviceTimeout, ProtocolError
            The camera did not acknowledge (the stream socket is closed regardless).
        """
        deadline = self._deadline(timeout_s)
        receiver, self._receiver = self._receiver, None
        if receiver is None and not self._acquiring:
            return
        self._acquiring = False
        failure: DeviceError | None = None
        if self.connected and self._link is not None:
            try:
                self._link.features.execute("AcquisitionStop", deadline)
                self._link.channel.write_register(gvcp.REG_SCP0, 0, deadline)
            except DeviceError as exc:
                failure = exc
        if receiver is not None:
            receiver.join()
        if self.connected and self._link is not None:
            error = unlock_quietly(self._link.features, deadline)
            if error is not None:
                logger.warning("%s: could not clear TLParamsLocked (%s)", self._name, error)
        if failure is not None and not isinstance(failure, DeviceDisconnected):
            try:
                raise failure
            finally:
                del failure

    # ------------------------------------------------------------------------------ life cycle
    def _disconnect(self, release: bool) -> None:
        self._beating.clear()
        if self._heartbeat is not None:
            self._heartbeat.join()
            self._heartbeat = None
        link, self._link = self._link, None
        if link is None:
            return
        if release and self._lost is None:
            try:
                link.channel.write_register(gvcp.REG_CCP, 0, time.monotonic() + min(self._timeout_s, 0.5))
            except DeviceError as exc:
                logger.info("%s: releasing control: %s", self._name, exc)
        link.channel.close()

    def close(self) -> None:
        """Stop acquisition, release control, close the sockets, end the threads. Idempotent."""
        if self._closed:
            return
        try:
            self.stop()
        except DeviceError as exc:
            logger.warning("%s: stopping while closing: %s", self._name, exc)
        finally:
            self._disconnect(release=True)
            self._closed = True
            self._ring.close(DeviceDisconnected(self._name, "camera closed"))
            self._heartbeat_role.close()
            if self._stream_role is not None:
                self._stream_role.close()

    def reopen(self, timeout_s: float) -> None:
        """Reconnect after the camera stopped answering: take control again, re-read its XML; acquisition
        resumes if it was running.

        Raises
        ------
        DeviceDisconnected, DeviceTimeout, ProtocolError
            As for :meth:`open`.
        """
        deadline = self._deadline(timeout_s)
        if self._closed:
            raise DeviceDisconnected(self._name, "camera was closed; open it again instead of reopen()")
        resume = self._acquiring
        receiver, self._receiver = self._receiver, None
        if receiver is not None:
            receiver.join()
        self._acquiring = False
        self._disconnect(release=False)
        self._ring.close(DeviceDisconnected(self._name, "connection replaced by reopen()"))
        self._connect(deadline)
        if resume:
            self.start(max(deadline - time.monotonic(), 0.001))

    def __enter__(self) -> GigECamera:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def _sleep_while(flag: threading.Event, seconds: float) -> bool:
    """Sleep ``seconds`` unless ``flag`` is cleared first; True when it is still set."""
    deadline = time.monotonic() + seconds
    while flag.is_set():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return True
        time.sleep(min(remaining, 0.02))
    return False


def _ipv4(address: str) -> int:
    parts = [int(p) for p in address.split(".")]
    return (parts[0] << 24) | (parts[1] << 16) | (parts[2] << 8) | parts[3]

