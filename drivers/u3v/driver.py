"""USB3 Vision camera over pyusb: control (GenCP), bootstrap, GenICam features and the stream.

:class:`U3VCamera` *has* a ``usb.core.Device``. The control channel
(:class:`~wavestack.drivers.u3v.control.ControlChannel`) serialises every command / acknowledge
exchange with a lock, so the user's thread and the stream thread never interleave on the control
endpoints. Finding and claiming the device is in :mod:`~wavestack.drivers.u3v.connection`. One
reader thread (:class:`~wavestack.drivers.u3v.acquisition.StreamReader`) assembles stream blocks
into :class:`Frame` values and puts them into a bounded :class:`FrameRing`; trouble on the stream
(timeouts, stalls, corrupt blocks) is counted and survived, an unplug closes the ring with one
``DeviceDisconnected``.
"""

from __future__ import annotations

import logging
import math
import struct
import threading
import time
from types import TracebackType
from typing import Any

import usb.core
import usb.util

from wavestack.drivers._checks import check_timeout
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, renewed
from wavestack.drivers.genicam.camera_features import CameraFeatures, unlock_quietly
from wavestack.drivers.genicam.camera_verbs import GenICamCamera
from wavestack.drivers.frames import Frame
from wavestack.drivers.ring import FrameRing, RingPolicy
from wavestack.drivers.role_thread import RoleThread
from wavestack.drivers.u3v import bootstrap as bs
from wavestack.drivers.ring_history import RingHistory
from wavestack.drivers.u3v.acquisition import StreamReader, U3VCounters, enable_stream
from wavestack.drivers.u3v.connection import (CONTROL_PROTOCOL, STREAM_PROTOCOL, U3V_CLASS, U3V_SUBCLASS, Link,
                                              attach, find_device, release)
from wavestack.drivers.u3v.stream import BlockAssembler

__all__ = ["CONTROL_PROTOCOL", "STREAM_PROTOCOL", "U3V_CLASS", "U3V_SUBCLASS", "U3VCamera", "U3VCounters"]

logger = logging.getLogger(__name__)


class U3VCamera(GenICamCamera):
    """A USB3 Vision camera (GenCP control + one image stream) driven through pyusb.

    Build it with :meth:`open`. Reading properties and setting features (the verbs of
    :class:`~wavestack.drivers.genicam.camera_verbs.GenICamCamera`, through the device's own GenICam
    node map) talk to the device; frames
    arrive through :meth:`start` / :meth:`read_frame` / :meth:`stop`. Use as a context manager or call
    :meth:`close`.
    """

    def __init__(self, *, backend: Any, serial: str | None, timeout_s: float, ring_capacity: int,
                 ring_policy: RingPolicy) -> None:
        check_timeout(timeout_s)
        self._backend = backend
        self._serial = serial
        self._timeout_s = timeout_s
        self._name = f"U3V camera{' ' + serial if serial else ''}"
        self._ring_capacity = ring_capacity
        self._ring_policy = RingPolicy(ring_policy)
        self._ring: FrameRing[Frame] = FrameRing(ring_capacity, self._ring_policy, name=self._name)
        self._history = RingHistory()
        self._state_lock = threading.Lock()
        self._stats = {"discarded_blocks": 0, "stalls_cleared": 0, "stream_timeouts": 0, "transfer_errors": 0}
        self._link: Link | None = None
        self._disconnected: DeviceDisconnected | None = None
        self._closed = False
        self._acquiring = False
        self._reader: StreamReader | None = None
        self._reader_role: RoleThread | None = None  # the reader's one thread for every acquisition

    # ----------------------------------------------------------------------------------- opening
    @classmethod
    def open(cls, *, backend: Any = None, serial: str | None = None, timeout_s: float, ring_capacity: int = 4,
             ring_policy: RingPolicy = RingPolicy.NEWEST_ONLY) -> U3VCamera:
        """Find a USB3 Vision camera, claim it and read its bootstrap registers and GenICam XML.

        Parameters
        ----------
        backend
            pyusb backend (``None``: libusb; tests pass the simulator's backend).
        serial
            USB serial number string to pick one camera; ``None`` takes the first found.
        timeout_s
            Longest time for the whole opening sequence, s; also the default for property reads
            and :meth:`stop`.
        ring_capacity, ring_policy
            The frame ring between the stream thread and :meth:`read_frame`.

        Raises
        ------
        ValueError
            Bad timeout or ring capacity (before any I/O).
        DeviceDisconnected
            No matching camera is plugged in.
        DeviceTimeout, ProtocolError
            The camera did not answer in time or answered outside the protocol.
        """
        camera = cls(backend=backend, serial=serial, timeout_s=timeout_s, ring_capacity=ring_capacity,
                     ring_policy=ring_policy)
        dev = find_device(backend, serial)
        if dev is None:
            raise DeviceDisconnected(camera._name, "expected a USB3 Vision device (interface class 0xEF/0x05) "
                                                   f"{'with serial ' + repr(serial) if serial else ''} to be "
                                                   "plugged in, found none")
        camera._connect(dev, time.monotonic() + timeout_s)
        return camera

    def _connect(self, dev: usb.core.Device, deadline: float) -> None:
        ids = f"{dev.idVendor:04x}:{dev.idProduct:04x}"
        self._name = f"U3V camera {ids}{' SN ' + self._serial if self._serial else ''}"
        try:
            link = attach(dev, deadline, self._name, self._mark_disconnected)
        except BaseException:
            usb.util.dispose_resources(dev)
            raise
        abrm = link.abrm
        self._serial = self._serial or abrm.serial_number or None
        self._name = f"U3V camera {ids} {abrm.model} SN {abrm.serial_number}"
        link.control.name = self._name
        link.features.node_map.device = self._name
        self._link = link
        self._ring = self._history.replace(self._ring, self._name)
        self._disconnected = None
        logger.info("%s: opened (GenCP %d.%d, max response %d ms)", self._name, *abrm.gencp_version,
                    abrm.max_response_time_ms)

    def _mark_disconnected(self, error: DeviceDisconnected) -> None:
        kept = renewed(error)  # the caller may raise ``error``: its traceback would keep the caller's frames
        with self._state_lock:
            if self._disconnected is None:
                self._disconnected = kept
        self._ring.close(kept)

    def _live(self) -> Link:
        if self._closed:
            raise DeviceDisconnected(self._name, "camera was closed; open it again")
        if self._disconnected is not None:
            raise DeviceDisconnected(self._name, "device was unplugged; replug it and call reopen()")
        if self._link is None:
            raise DeviceDisconnected(self._name, "not connected")
        return self._link

    # ---------------------------------------------------------------------------------- features
    def _camera_features(self) -> CameraFeatures:
        return self._live().features

    @property
    def connected(self) -> bool:
        """True while the connection is usable (not closed, not unplugged since it was opened)."""
        return not self._closed and self._disconnected is None and self._link is not None

    def present(self) -> bool:
        """True if the camera (by serial) is on the bus: a cheap check before :meth:`reopen`."""
        return not self._closed and find_device(self._backend, self._serial) is not None

    @property
    def device_info(self) -> bs.Abrm:
        """Identification and timing read from the ABRM at open."""
        return self._live().abrm

    # --------------------------------------------------------------------------------- streaming
    def start(self, timeout_s: float | None = None) -> None:
        """Lock the transport layer, configure the SIRM transfer sizes, enable the stream, AcquisitionStart,
        start the reader.

        As a GenTL producer does (SFNC), ``AcquisitionMode`` is set to ``Continuous`` and
        ``TLParamsLocked`` to 1 first, when the device describes them; :meth:`stop` clears the lock.

        Frames pending from an earlier acquisition are dropped (counted). Idempotent while running.
        """
        deadline = self._deadline(timeout_s)
        link = self._live()
        if self._reader is not None:
            return
        link.features.lock_transport_layer(deadline)
        try:
            sirm, sizes = enable_stream(link.control, link.sbrm.sirm_address, deadline, self._name)
            if self._ring.closed:  # the last reader gave up after repeated stream errors: start afresh
                self._ring = self._history.replace(self._ring, self._name)
            self._ring.discard_pending()
            link.features.execute("AcquisitionStart", deadline)
        except DeviceError:
            self._log_unlock_failure(unlock_quietly(link.features, deadline))
            raise
        self._acquiring = True
        assembler = BlockAssembler(sizes, sirm.required_payload_size, self._name)
        self._reader_role = self._reader_role or RoleThread(f"u3v-reader {self._serial or ''}".strip(), daemon=True)
        self._reader = StreamReader(link.dev, link.stream_ep, assembler, self._ring, self._name, self._count,
                                    self._mark_disconnected, self._reader_role)
        self._reader.start()
        logger.info("%s: streaming, payload %d B in %d x %d B + %d + %d", self._name, sirm.required_payload_size,
                    sizes.payload_count, sizes.payload_size, sizes.final1_size, sizes.final2_size)

    @property
    def reading(self) -> bool:
        """True from :meth:`start` until :meth:`stop`, an unplug or too many stream errors (the thread stays)."""
        return self._reader is not None and self._reader.running

    def counters(self) -> U3VCounters:
        """Frame counters over the camera's life, across reconnects, and stream health (see :class:`U3VCounters`)."""
        with self._state_lock:
            stats = dict(self._stats)
        c = self._history.with_current(self._ring)
        return U3VCounters(c.acquired, c.delivered, c.dropped, c.dropped_in_gaps, c.pending, **stats)

    def _count(self, key: str) -> None:
        with self._state_lock:
            self._stats[key] += 1

    def _join_reader(self) -> None:
        reader, self._reader = self._reader, None
        if reader is not None:
            reader.join()

    def stop(self, timeout_s: float | None = None) -> None:
        """AcquisitionStop, stop and join the reader thread, disable the stream, clear TLParamsLocked.
        Idempotent. After an unplug only the thread is joined. Pending frames stay readable.

        Raises
        ------
        DeviceTimeout, ProtocolError
            The device did not acknowledge AcquisitionStop or the stream disable (the thread is
            joined regardless).
        """
        deadline = self._deadline(timeout_s)
        if self._reader is None and not self._acquiring:
            return
        self._acquiring = False
        failure: DeviceError | None = None
        if self._disconnected is None and not self._closed and self._link is not None:
            try:
                self._link.features.execute("AcquisitionStop", deadline)
            except DeviceError as exc:
                failure = exc
        self._join_reader()
        if self._disconnected is None and not self._closed and self._link is not None:
            try:
                self._link.control.write(self._link.sbrm.sirm_address + bs.SIRM_SI_CONTROL, struct.pack("<I", 0),
                                         deadline, "SIRM stream disable")
            except DeviceError as exc:
                failure = failure or exc
            self._log_unlock_failure(unlock_quietly(self._link.features, deadline))
        if failure is not None and not isinstance(failure, DeviceDisconnected):
            try:
                raise failure
            finally:
                del failure  # no local naming the error: a cycle with this frame (errors.renewed)

    def _log_unlock_failure(self, error: DeviceError | None) -> None:
        if error is not None:
            logger.warning("%s: could not clear TLParamsLocked (%s)", self._name, error)

    # ------------------------------------------------------------------------------ life cycle
    def _release(self) -> None:
        link, self._link = self._link, None
        if link is not None:
            release(link, self._name)

    def close(self) -> None:
        """Stop acquisition, join the reader, release the interfaces and USB resources. Idempotent."""
        if self._closed:
            return
        try:
            self.stop()
        except DeviceError as exc:
            logger.warning("%s: stopping while closing: %s", self._name, exc)
        finally:
            self._join_reader()
            if self._reader_role is not None:  # the reader's thread ends with the camera
                self._reader_role.close()
            self._closed = True
            self._ring.close(DeviceDisconnected(self._name, "camera closed"))
            self._release()

    def reopen(self, timeout_s: float) -> None:
        """Reconnect after an unplug/replug: find the same camera (by serial), re-read its bootstrap.

        Waits up to ``timeout_s`` for the camera to re-enumerate. A fresh frame ring replaces the
        closed one (the counters carry on); if acquisition was running when the camera went away (and
        :meth:`stop` was not called since), it is started again.

        Raises
        ------
        DeviceDisconnected
            The camera did not re-enumerate within ``timeout_s``, or the camera was closed.
        DeviceTimeout, ProtocolError
            As for :meth:`open`.
        """
        deadline = self._deadline(timeout_s)
        if self._closed:
            raise DeviceDisconnected(self._name, "camera was closed; open it again instead of reopen()")
        resume = self._acquiring  # kept across failed attempts: a later reopen() still resumes
        self._join_reader()
        self._release()
        self._ring.close(DeviceDisconnected(self._name, "connection replaced by reopen()"))
        while (dev := find_device(self._backend, self._serial)) is None:
            if time.monotonic() >= deadline:
                raise DeviceDisconnected(self._name, f"expected the camera to re-enumerate within {timeout_s:g} s")
            time.sleep(0.05)
        self._connect(dev, deadline)
        self._acquiring = False
        if resume:
            self.start(max(deadline - time.monotonic(), 0.001))

    def __enter__(self) -> U3VCamera:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
