"""Where the station's sets of frames come from: a free-running camera, or piezo-stepped phase sets.

Both hand the pipeline the *newest* set and count what a slow pipeline skipped, so a slow stage
drops frames instead of building a backlog. Both count frames and sets separately
(:class:`~wavestack.station.counters.Counters`, each count adding up exactly):

- :class:`CarrierSource` — one frame per set, straight from the camera driver's own stream thread
  and newest-only ring;
- :class:`PhaseStepSource` — a thread of its own steps the piezo, triggers the camera per step,
  tags each frame with the commanded and read-back voltage, and puts whole sets into a newest-only
  ring of sets; a device error ends the thread and is handed to the pipeline through the ring.
  A block the camera discarded (damaged leader, trailer or payload) costs only the set it
  belonged to (:class:`~wavestack.drivers.ring.FrameLost`, at once), up to
  :data:`MAX_LOST_SETS_IN_A_ROW` sets in a row. A stop is seen within one 0.1 s wait slice, one
  piezo exchange, or at once during a settle wait; the thread never raises.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence

from wavestack.drivers.errors import DeviceError, ProtocolError, renewed
from wavestack.drivers.frames import Frame
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration, acquire_phase_steps
from wavestack.drivers.mdt693b.phase_stepping import AcquisitionCancelled
from wavestack.drivers.ring import FrameLost, FrameRing, RingPolicy, WaitTimeout
from wavestack.drivers.role_thread import Job, RoleThread
from wavestack.drivers.gige import GigECamera
from wavestack.drivers.u3v import U3VCamera
from wavestack.station.counters import Counters, FrameCounts, SetCounts

logger = logging.getLogger(__name__)

_WAIT_SLICE_S = 0.1  # longest a stepping thread waits for a frame before it looks at its stop flag
MAX_LOST_SETS_IN_A_ROW = 3  # sets given up for a lost frame before the source reports the camera as failing


class _CameraFrames:
    """The camera's frame counters since a source started: (acquired, delivered, dropped, pending).

    Frames the camera delivered or dropped before are not this source's; frames pending then are
    (the camera's start drops them, counted).
    """

    def __init__(self, camera: U3VCamera | GigECamera) -> None:
        self._camera = camera
        before = camera.counters()
        self._before = (before.delivered, before.dropped)

    def now(self) -> tuple[int, int, int, int]:
        c = self._camera.counters()
        delivered, dropped = self._before
        return c.acquired - delivered - dropped, c.delivered - delivered, c.dropped - dropped, c.pending


class CarrierSource:
    """Single carrier frames from a free-running camera.

    A set is one frame, so frames and sets count alike: the camera ring's counters (since
    :meth:`start`), where every frame delivered is a frame the pipeline processes (it processes
    every set it reads).
    """

    frames_per_set = 1

    def __init__(self, camera: U3VCamera | GigECamera) -> None:
        self._camera = camera
        self._frames: _CameraFrames | None = None

    def start(self) -> None:
        self._frames = _CameraFrames(self._camera)
        self._camera.start()

    def read_set(self, timeout_s: float) -> tuple[Frame, ...]:
        """The newest frame, as a set of one."""
        return (self._camera.read_frame(timeout_s),)

    def counters(self) -> Counters:
        """Frames and sets since :meth:`start` (the pipeline's thread calls this between sets)."""
        if self._frames is None:
            return Counters.zero(1)
        acquired, delivered, dropped, pending = self._frames.now()
        return Counters(1, FrameCounts(acquired, delivered, dropped, pending),
                        SetCounts(acquired, delivered, dropped, pending))

    def stop(self) -> None:
        self._camera.stop()


class _SetInHand:
    """The camera as the stepping sequence sees it, counting the frames read for the set in hand.

    A frame is awaited in slices of at most :data:`_WAIT_SLICE_S`, so a stop is seen within one
    slice; a block the camera discarded after the trigger ends the wait at once
    (:class:`~wavestack.drivers.ring.FrameLost`) instead of after the whole timeout.
    """

    def __init__(self, camera: U3VCamera | GigECamera, stop: threading.Event, frame_timeout_s: float) -> None:
        self._camera = camera
        self._stop = stop
        self._frame_timeout_s = frame_timeout_s
        self._loss_mark = camera.loss_mark()
        self.frames = 0

    def trigger_software(self, timeout_s: float) -> None:
        self._loss_mark = self._camera.loss_mark()
        self._camera.trigger_software(timeout_s)

    def read_frame(self, timeout_s: float) -> Frame:
        """The triggered frame, within the station's frame timeout (``timeout_s`` bounds device calls)."""
        deadline = time.monotonic() + self._frame_timeout_s
        while True:
            if self._stop.is_set():
                raise AcquisitionCancelled(f"{self._camera.name}: stopped while waiting for a triggered frame")
            remaining = deadline - time.monotonic()
            try:
                frame = self._camera.read_frame(max(0.0, min(_WAIT_SLICE_S, remaining)),
                                                since_loss=self._loss_mark)
            except WaitTimeout:
                if remaining <= _WAIT_SLICE_S:
                    raise
                continue
            self.frames += 1
            return frame


class PhaseStepSource:
    """Phase-shifted sets: the piezo steps, the camera takes one triggered frame per step.

    Parameters
    ----------
    camera : U3VCamera or GigECamera
        In trigger mode.
    piezo : MDT693B
        Open.
    axis : str
        Piezo output moving the reference mirror.
    steps_rad : sequence of float
        Phase steps of one set.
    calibration : PhaseStepCalibration
    settle_s, timeout_s : float
        Wait after each step; timeout of each device call, s.
    frame_timeout_s : float, optional
        Longest wait for a triggered frame before the camera counts as failing, s (default
        ``timeout_s``); the station passes its ``frame_timeout_s``.
    ring_capacity : int
        Sets held for the pipeline (newest-only).
    role : RoleThread, optional
        The thread the stepping runs on; the station passes its own, the same for every source, so
        a reconnect starts no new thread (:mod:`~wavestack.drivers.role_thread`: a new thread gets a
        new malloc arena). Default: a thread of this source's own.

    Notes
    -----
    A frame the camera delivered is in a set in the ring (or processed, or dropped with its set),
    in the set being assembled, or lost with a set a device error left unfinished. The stepping
    thread puts a set and counts a lost one under ``_count_lock``, and :meth:`counters` reads the
    set ring, the lost frames and the camera under the same lock, so the frames in assembly
    (camera delivered minus those accounted for) are between 0 and one set, and checked to be.
    """

    def __init__(self, camera: U3VCamera | GigECamera, piezo: MDT693B, *, axis: str, steps_rad: Sequence[float],
                 calibration: PhaseStepCalibration, settle_s: float, timeout_s: float, ring_capacity: int,
                 frame_timeout_s: float | None = None, role: RoleThread | None = None) -> None:
        self._camera = camera
        self._piezo = piezo
        self._axis = axis
        self._steps = tuple(float(s) for s in steps_rad)
        self._calibration = calibration
        self._settle_s = settle_s
        self._timeout_s = timeout_s
        self._frame_timeout_s = timeout_s if frame_timeout_s is None else frame_timeout_s
        self._capacity = ring_capacity
        self._ring: FrameRing[tuple[Frame, ...]] = FrameRing(ring_capacity, RingPolicy.NEWEST_ONLY, name="phase sets")
        self._stop = threading.Event()
        self._role = role
        self._thread: threading.Thread | Job | None = None
        self._sets = 0
        self._count_lock = threading.Lock()
        self._lost_frames = 0  # read for a set that a device error left unfinished
        self._frames: _CameraFrames | None = None

    @property
    def frames_per_set(self) -> int:
        return len(self._steps)

    def start(self) -> None:
        """Start the camera and the stepping thread (once: a station makes a new source to restart)."""
        if self._frames is not None:
            raise RuntimeError("PhaseStepSource.start: already started; make a new source to restart")
        self._frames = _CameraFrames(self._camera)
        self._camera.start()
        self._stop.clear()
        if self._role is not None:
            self._thread = self._role.run(self._run)
        else:
            self._thread = threading.Thread(target=self._run, name="phase-step-acquisition")
            self._thread.start()

    def _run(self) -> None:
        """The stepping thread: sets into the ring until stopped or a device fails; never raises."""
        lost_in_a_row = 0
        while not self._stop.is_set():
            in_hand = _SetInHand(self._camera, self._stop, self._frame_timeout_s)
            try:
                frames = acquire_phase_steps(self._piezo, in_hand, self._axis, self._steps,
                                             calibration=self._calibration, settle_s=self._settle_s,
                                             timeout_s=self._timeout_s, cancel=self._stop)
            except FrameLost as error:  # one damaged block: this set is lost, the next one goes on
                self._count_lost(in_hand)
                lost_in_a_row += 1
                # the text, not the error: a log record kept by a handler would keep its frames
                logger.warning("phase-step set given up (%d in a row): %s", lost_in_a_row, str(error))
                self._camera.discard_pending()  # a late frame of the lost set must not start the next one
                if lost_in_a_row >= MAX_LOST_SETS_IN_A_ROW:
                    self._ring.close(renewed(error))  # a copy without the traceback, as below
                    return
                continue
            except AcquisitionCancelled:
                self._count_lost(in_hand)
                return
            except DeviceError as error:
                self._count_lost(in_hand)
                if not self._stop.is_set():
                    logger.warning("phase-step acquisition stopped: %s", str(error))  # the text, as above
                    # a fresh copy: the raised error's traceback holds this frame (self, the source, its
                    # ring of sets) and the half-read set, a cycle only the cyclic collector would free
                    self._ring.close(renewed(error))
                return
            except Exception as error:  # a bug must not leave the pipeline waiting, nor raise in a thread
                self._count_lost(in_hand)
                logger.exception("phase-step acquisition failed")
                self._ring.close(ProtocolError(self._piezo.name, f"phase-step acquisition failed: {error!r}"))
                return
            lost_in_a_row = 0
            with self._count_lock:
                self._ring.put(frames, frame_id=self._sets)
            self._sets += 1

    def _count_lost(self, in_hand: _SetInHand) -> None:
        with self._count_lock:
            self._lost_frames += in_hand.frames

    def read_set(self, timeout_s: float) -> tuple[Frame, ...]:
        """The newest complete set."""
        return self._ring.get(timeout_s)

    def counters(self) -> Counters:
        """Frames and sets so far (see the class notes for how they add up).

        Raises
        ------
        ValueError
            The frames in assembly are not between 0 and one set (the counts do not add up).
        """
        n = self.frames_per_set
        if self._frames is None:
            return Counters.zero(n)
        with self._count_lock:
            sets = self._ring.counters()
            lost = self._lost_frames
            acquired, delivered, dropped, pending = self._frames.now()
        in_assembly = delivered - n * sets.acquired - lost
        if not 0 <= in_assembly <= n:
            raise ValueError(f"phase-step counters: {delivered} frames delivered by the camera, {sets.acquired} "
                             f"sets of {n} assembled and {lost} lost leave {in_assembly} in assembly; expected 0..{n}")
        return Counters(n, FrameCounts(acquired, n * sets.delivered, dropped + n * sets.dropped + lost,
                                       pending + n * sets.pending + in_assembly),
                        SetCounts(sets.acquired, sets.delivered, sets.dropped, sets.pending))

    def stop(self) -> None:
        """Stop the stepping thread and the camera; idempotent."""
        self._stop.set()
        if self._thread is not None:
            # the thread sees the stop within one wait slice or one piezo exchange (settle waits are cut short)
            self._thread.join(timeout=self._timeout_s * 2 + 5.0)
            if self._thread.is_alive():
                logger.error("phase-step thread still running %.0f s after the stop", self._timeout_s * 2 + 5.0)
            self._thread = None
        self._ring.close()
        try:
            self._camera.stop()
        except DeviceError as error:
            logger.info("camera stop: %s", error)
