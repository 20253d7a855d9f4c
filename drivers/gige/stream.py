"""The GVSP stream channel of one acquisition: its socket, and the thread that turns packets into frames.

:class:`StreamReceiver` binds a UDP socket on the host (its port goes into the camera's SCP0
register), reads every packet, feeds a :class:`~wavestack.drivers.gige.gvsp.BlockAssembler`, asks
the camera again for missing packets (PACKETRESEND over the control channel), and puts complete
images into the frame ring in block order (an image is never released ahead of an older block
still being recovered). Lost blocks show up as gaps in the frame ids, which the ring counts as
dropped. The 16-bit GVSP block id (1..65535, then 1 again) becomes a frame id that only grows.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable

from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.frames import Frame
from wavestack.drivers.gige import gvcp, gvsp
from wavestack.drivers.gige.control import ControlChannel
from wavestack.drivers.ring import FrameRing
from wavestack.drivers.role_thread import Job, RoleThread

logger = logging.getLogger(__name__)

RECEIVE_BUFFER = 16 << 20  # a few 1024 x 1024 Mono12 images; the kernel may grant less (net.core.rmem_max)
_POLL_S = 0.01


def _grow_receive_buffer(sock: socket.socket, device: str) -> None:
    """Ask for :data:`RECEIVE_BUFFER` bytes of kernel buffer, beyond ``net.core.rmem_max`` where allowed
    (SO_RCVBUFFORCE needs CAP_NET_ADMIN); a smaller grant is logged, since a full buffer loses packets
    that then cost resends."""
    force = getattr(socket, "SO_RCVBUFFORCE", None)
    try:
        if force is None:
            raise PermissionError
        sock.setsockopt(socket.SOL_SOCKET, force, RECEIVE_BUFFER)
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
    granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    if granted < RECEIVE_BUFFER:
        logger.info("%s: stream receive buffer %d B (asked %d B; raise net.core.rmem_max for fewer resends)",
                    device, granted, RECEIVE_BUFFER)


class _BlockIds:
    """16-bit GVSP block ids (1..0xFFFF cyclic) to ids that only grow."""

    def __init__(self) -> None:
        self._raw: int | None = None
        self._full = 0

    def full(self, raw: int) -> int:
        if self._raw is None:
            self._raw, self._full = raw, raw
            return raw
        ahead = (raw - self._raw) % 0xFFFF
        if ahead < 0x8000:
            self._raw, self._full = raw, self._full + ahead
            return self._full
        return self._full - ((self._raw - raw) % 0xFFFF)


class StreamReceiver:
    """Receives one acquisition's stream on the camera's stream role thread.

    Parameters
    ----------
    device
        Name for messages.
    channel
        The control channel (for PACKETRESEND).
    ring
        Where the frames go.
    bind_host
        Host address the camera streams to (the control socket's local address).
    data_size
        Payload bytes per data packet.
    max_payload
        The largest image the host accepts, bytes.
    count
        Called with a stream-health counter's name (``"packets"``, ``"bad_packets"``,
        ``"resend_requests"``, ``"blocks_dropped"``) each time one happens.
    role
        The camera's stream thread, the same for every acquisition.
    """

    def __init__(self, device: str, channel: ControlChannel, ring: FrameRing[Frame], bind_host: str, data_size: int,
                 max_payload: int, count: Callable[[str, int], None], role: RoleThread) -> None:
        self._device = device
        self._channel = channel
        self._ring = ring
        self._count = count
        self._role = role
        self._stop = threading.Event()
        self._job: Job | None = None
        self._assembler = gvsp.BlockAssembler(device, data_size, max_payload)
        self._ids = _BlockIds()
        self._ready: dict[int, gvsp.Image] = {}  # complete images waiting for older blocks
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            _grow_receive_buffer(self._sock, device)
            self._sock.bind((bind_host, 0))
            self._sock.settimeout(_POLL_S)
        except OSError:
            self._sock.close()
            raise
        self.port = self._sock.getsockname()[1]

    def start(self) -> None:
        self._job = self._role.run(self._run)

    @property
    def running(self) -> bool:
        return self._job is not None and self._job.is_alive()

    def join(self) -> None:
        """Stop reading and close the socket (within one poll interval)."""
        self._stop.set()
        if self._job is not None:
            self._job.join()
        self._sock.close()

    def _run(self) -> None:
        buffer = bytearray(gvsp.MAX_PACKET + 1)
        view = memoryview(buffer)
        next_tick = time.monotonic() + _POLL_S
        try:
            while not self._stop.is_set():
                try:
                    size = self._sock.recv_into(buffer)
                except TimeoutError:
                    size = 0
                now = time.monotonic()
                if size:
                    self._count("packets", 1)
                    try:
                        packet = gvsp.parse_packet(view[:size], self._device)
                    except ProtocolError as error:
                        self._count("bad_packets", 1)
                        logger.debug("%s: %s", self._device, error.detail)
                    else:
                        self._handle(self._assembler.feed(packet, now))
                if now >= next_tick:
                    next_tick = now + _POLL_S
                    self._handle(self._assembler.tick(now))
        except Exception as exc:  # a bug must not leave a consumer waiting forever
            logger.exception("%s: stream receiver failed", self._device)
            self._ring.close(ProtocolError(self._device, f"stream receiver failed: {exc!r}"))

    def _handle(self, progress: gvsp.Progress) -> None:
        for block_id, first, last in progress.resend:
            self._count("resend_requests", 1)
            self._channel.send_only(lambda i, b=block_id, f=first, t=last: gvcp.encode_packetresend(i, 0, b, f, t))
        for block_id, reason in progress.dropped:
            self._count("blocks_dropped", 1)
            logger.info("%s: block %d dropped: %s", self._device, block_id, reason)
            self._ring.note_loss()
        for image in progress.images:
            self._ready[self._ids.full(image.block_id)] = image
        if self._ready:
            self._release()

    def _release(self) -> None:
        pending = [self._ids.full(block_id) for block_id in self._assembler.pending_ids()]
        oldest_pending = min(pending) if pending else None
        for full_id in sorted(self._ready):
            if oldest_pending is not None and full_id > oldest_pending:
                break
            image = self._ready.pop(full_id)
            frame = Frame(frame_id=full_id, host_time_ns=time.time_ns(), device_timestamp=image.leader.timestamp,
                          pixels=image.pixels,
                          metadata={"pixel_format": gvsp.PIXEL_FORMAT_NAMES[image.leader.pixel_format]})
            self._ring.put(frame, frame_id=full_id)
