"""Acquisition on a USB3 Vision camera: enabling the stream, the thread that reads it, its counters.

:func:`enable_stream` writes the SIRM transfer sizes and enables the stream interface;
:class:`StreamReader` is the one reader thread of an acquisition, which assembles stream blocks
into :class:`Frame` values and puts them into a bounded :class:`FrameRing`. Trouble on the stream
(timeouts, stalls, corrupt blocks) is counted and survived (see :class:`U3VCounters`); an unplug
closes the ring with one ``DeviceDisconnected``.
"""

from __future__ import annotations

import errno
import logging
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import usb.core

from wavestack.drivers.errors import DeviceDisconnected, ProtocolError
from wavestack.drivers.frames import Frame
from wavestack.drivers.ring import FrameRing
from wavestack.drivers.role_thread import Job, RoleThread
from wavestack.drivers.u3v import bootstrap as bs
from wavestack.drivers.u3v.control import ControlChannel
from wavestack.drivers.u3v.stream import AssembledBlock, BlockAssembler, DiscardedBlock

logger = logging.getLogger(__name__)

_STREAM_READ_TIMEOUT_MS = 100  # short, so stop() is prompt; a timeout only means "no frame yet"
_MAX_STREAM_TRANSFER = 1 << 20
_MAX_CONSECUTIVE_STREAM_ERRORS = 50


@dataclass(frozen=True)
class U3VCounters:
    """Frame counters (``acquired == delivered + dropped + pending``) and stream health.

    The frame counters cover the camera's whole life (every ring, across reconnects; see
    :class:`RingHistory`), so they never go backwards.

    Attributes
    ----------
    acquired, delivered, dropped, dropped_in_gaps, pending
        As in :class:`wavestack.drivers.ring.RingCounters`.
    discarded_blocks
        Blocks (or runs of transfers) thrown away as corrupt, short or out of order; lost blocks
        also show up in ``dropped`` through the gap in block ids.
    stalls_cleared
        Stream endpoint stalls (EPIPE) cleared with ``clear_halt``.
    stream_timeouts
        Stream reads that timed out (normal while waiting for a trigger).
    transfer_errors
        Other USB errors on the stream endpoint.
    """

    acquired: int
    delivered: int
    dropped: int
    dropped_in_gaps: int
    pending: int
    discarded_blocks: int
    stalls_cleared: int
    stream_timeouts: int
    transfer_errors: int


def enable_stream(control: ControlChannel, sirm_address: int, deadline: float,
                  device: str) -> tuple[bs.Sirm, bs.TransferSizes]:
    """Configure the SIRM transfer sizes and enable the stream interface.

    A stream left enabled by an earlier session is disabled first (its transfer sizes are locked
    while enabled).

    Parameters
    ----------
    control
        The camera's control channel.
    sirm_address
        Address of the SIRM (from the SBRM).
    deadline
        ``time.monotonic()`` value by which every write must be acknowledged, s.
    device
        Device name for messages.

    Returns
    -------
    (Sirm, TransferSizes)
        The SIRM as read before configuring it, and the transfer sizes written into it.

    Raises
    ------
    DeviceTimeout, ProtocolError
        The device did not acknowledge in time, or reports a required payload size of 0.
    """
    sirm = bs.decode_sirm(control.read(sirm_address, bs.SIRM_SIZE, deadline, "SIRM"), device)
    if sirm.stream_enabled:  # left enabled by an earlier session: the transfer sizes are locked
        control.write(sirm_address + bs.SIRM_SI_CONTROL, struct.pack("<I", 0), deadline, "SIRM")
    if sirm.required_payload_size < 1:
        raise ProtocolError(device, "SIRM required payload size is 0; expected an image size")
    sizes = bs.compute_transfer_sizes(sirm.required_payload_size, max(sirm.required_leader_size, 52),
                                      max(sirm.required_trailer_size, 32), sirm.alignment,
                                      max(_MAX_STREAM_TRANSFER, sirm.alignment))
    for offset, value in ((bs.SIRM_MAX_LEADER_SIZE, sizes.max_leader_size),
                          (bs.SIRM_PAYLOAD_TRANSFER_SIZE, sizes.payload_size),
                          (bs.SIRM_PAYLOAD_TRANSFER_COUNT, sizes.payload_count),
                          (bs.SIRM_FINAL_TRANSFER1_SIZE, sizes.final1_size),
                          (bs.SIRM_FINAL_TRANSFER2_SIZE, sizes.final2_size),
                          (bs.SIRM_MAX_TRAILER_SIZE, sizes.max_trailer_size)):
        control.write(sirm_address + offset, struct.pack("<I", value), deadline, "SIRM")
    control.write(sirm_address + bs.SIRM_SI_CONTROL, struct.pack("<I", bs.SI_CONTROL_STREAM_ENABLE),
                  deadline, "SIRM stream enable")
    return sirm, sizes


class StreamReader:
    """The reader of one acquisition, on the camera's reader thread: bulk reads -> blocks -> frames in the ring.

    It reads from :meth:`start` until :meth:`join`, an unplug, or more than 50 stream errors in a
    row (which close the ring with a ``ProtocolError``).

    Parameters
    ----------
    dev
        The camera's ``usb.core.Device``.
    stream_ep
        Address of the bulk IN stream endpoint.
    assembler
        Block assembler configured for this acquisition's transfer sizes.
    ring
        Where the frames go.
    device
        Device name for messages.
    count
        Called with the name of a stream-health counter (``"discarded_blocks"``,
        ``"stalls_cleared"``, ``"stream_timeouts"``, ``"transfer_errors"``) each time one happens.
    on_disconnect
        Called when the reader finds the camera unplugged.
    role
        The camera's reader thread (:class:`~wavestack.drivers.role_thread.RoleThread`), the same
        for every acquisition: a new thread per acquisition would get a new malloc arena at each
        reconnect (see that module).
    """

    def __init__(self, dev: usb.core.Device, stream_ep: int, assembler: BlockAssembler, ring: FrameRing[Frame],
                 device: str, count: Callable[[str], None], on_disconnect: Callable[[DeviceDisconnected], None],
                 role: RoleThread) -> None:
        self._dev = dev
        self._stream_ep = stream_ep
        self._assembler = assembler
        self._ring = ring
        self._name = device
        self._count = count
        self._mark_disconnected = on_disconnect
        self._stop = threading.Event()
        self._role = role
        self._job: Job | None = None

    def start(self) -> None:
        """Start reading on the role's thread."""
        self._job = self._role.run(self._read_stream)

    @property
    def running(self) -> bool:
        """True from :meth:`start` until the reader has stopped (joined, unplugged, or given up)."""
        return self._job is not None and self._job.is_alive()

    def join(self) -> None:
        """Ask the reader to stop and wait until it has (within one short stream read)."""
        self._stop.set()
        if self._job is not None:
            self._job.join()

    def _read_stream(self) -> None:
        """The reader thread: bulk reads -> blocks -> frames in the ring, until stopped or unplugged."""
        errors_in_a_row = 0
        try:
            while not self._stop.is_set():
                try:
                    data = self._dev.read(self._stream_ep, self._assembler.next_read_size(),
                                      timeout=_STREAM_READ_TIMEOUT_MS)
                except usb.core.USBTimeoutError:
                    self._count("stream_timeouts")  # not an error: the camera may be waiting for a trigger
                    continue
                except usb.core.USBError as exc:
                    if exc.errno == errno.ENODEV:
                        self._mark_disconnected(DeviceDisconnected(self._name, "unplugged during acquisition"))
                        return
                    errors_in_a_row += 1
                    self._recover(exc)
                    if errors_in_a_row > _MAX_CONSECUTIVE_STREAM_ERRORS:
                        self._ring.close(ProtocolError(self._name, f"stream failed {errors_in_a_row} times in a "
                                                                   f"row, last: {exc}"))
                        return
                    continue
                errors_in_a_row = 0
                self._deliver(self._assembler.feed(data))
        except DeviceDisconnected as exc:  # recovering found the device gone
            self._mark_disconnected(exc)
        except Exception as exc:  # a bug must not leave a consumer waiting forever
            logger.exception("%s: stream reader failed", self._name)
            self._ring.close(ProtocolError(self._name, f"stream reader failed: {exc!r}"))

    def _recover(self, exc: usb.core.USBError) -> None:
        if exc.errno == errno.EPIPE:
            logger.warning("%s: stream endpoint stalled; clearing the halt and resynchronising", self._name)
            try:
                self._dev.clear_halt(self._stream_ep)
            except usb.core.USBError as halt_exc:
                if halt_exc.errno == errno.ENODEV:
                    raise DeviceDisconnected(self._name, "unplugged while clearing a stall") from None
                logger.warning("%s: clear_halt failed: %s", self._name, halt_exc)
            else:
                self._count("stalls_cleared")
        else:
            logger.warning("%s: stream transfer error %s; resynchronising", self._name, exc)
            self._count("transfer_errors")
        self._deliver(self._assembler.abort(f"USB error {exc}"))

    def _deliver(self, outcome: AssembledBlock | DiscardedBlock | None) -> None:
        if isinstance(outcome, DiscardedBlock):
            logger.warning("%s: discarded block %s: %s", self._name, outcome.block_id, outcome.reason)
            self._count("discarded_blocks")
            self._ring.note_loss()
        elif isinstance(outcome, AssembledBlock):
            leader = outcome.leader
            frame = Frame(frame_id=leader.block_id, host_time_ns=time.time_ns(), device_timestamp=leader.timestamp,
                          pixels=outcome.pixels, metadata={"pixel_format": leader.pixel_format_name})
            self._ring.put(frame, frame_id=leader.block_id)
