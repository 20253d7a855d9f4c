"""Where the station's sets of frames come from: a free-running camera, or piezo-stepped phase sets.

Both hand the pipeline the *newest* set and count what a slow pipeline skipped, so a slow stage
drops frames instead of building a backlog. Both count frames and sets separately
(:class:`~wavestack.station.counters.Counters`, each count adding up exactly):

- :class:`CarrierSource` — one frame per set, straight from the camera driver's own stream thread
  and newest-only ring;
- :class:`PhaseStepSource` — a thread of its own steps the piezo, triggers the camera per step,
  tags each frame with the commanded and read-back voltage, and puts whole sets into a newest-only
  ring of sets; a device error ends the thread and is handed to the pipeline through the ring.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence

from wavestack.drivers.errors import DeviceError
from wavestack.drivers.frames import Frame
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration, acquire_phase_steps
from wavestack.drivers.ring import FrameRing, RingPolicy
from wavestack.drivers.u3v import U3VCamera
from wavestack.station.counters import Counters, FrameCounts, SetCounts

logger = logging.getLogger(__name__)


class _CameraFrames:
    """The camera's frame counters since a source started: (acquired, delivered, dropped, pending).

    Frames the camera delivered or dropped before are not this source's; frames pending then are
    (the camera's start drops them, counted).
    """

    def __init__(self, camera: U3VCamera) -> None:
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

    def __init__(self, camera: U3VCamera) -> None:
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
    """The camera as the stepping sequence sees it, counting the frames read for the set in hand."""

    def __init__(self, camera: U3VCamera) -> None:
        self._camera = camera
        self.frames = 0

    def trigger_software(self, timeout_s: float) -> None:
        self._camera.trigger_software(timeout_s)

    def read_frame(self, timeout_s: float) -> Frame:
        frame = self._camera.read_frame(timeout_s)
        self.frames += 1
        return frame


class PhaseStepSource:
    """Phase-shifted sets: the piezo steps, the camera takes one triggered frame per step.

    Parameters
    ----------
    camera : U3VCamera
        In trigger mode.
    piezo : MDT693B
        Open.
    axis : str
        Piezo output moving the reference mirror.
    steps_rad : sequence of float
        Phase steps of one set.
    calibration : PhaseStepCalibration
    settle_s, timeout_s : float
        Wait after each step; timeout of each device call.
    ring_capacity : int
        Sets held for the pipeline (newest-only).

    Notes
    -----
    A frame the camera delivered is in a set in the ring (or processed, or dropped with its set),
    in the set being assembled, or lost with a set a device error left unfinished. The stepping
    thread puts a set and counts a lost one under ``_count_lock``, and :meth:`counters` reads the
    set ring, the lost frames and the camera under the same lock, so the frames in assembly
    (camera delivered minus those accounted for) are between 0 and one set, and checked to be.
    """

    def __init__(self, camera: U3VCamera, piezo: MDT693B, *, axis: str, steps_rad: Sequence[float],
                 calibration: PhaseStepCalibration, settle_s: float, timeout_s: float, ring_capacity: int) -> None:
        self._camera = camera
        self._piezo = piezo
        self._axis = axis
        self._steps = tuple(float(s) for s in steps_rad)
        self._calibration = calibration
        self._settle_s = settle_s
        self._timeout_s = timeout_s
        self._capacity = ring_capacity
        self._ring: FrameRing[tuple[Frame, ...]] = FrameRing(ring_capacity, RingPolicy.NEWEST_ONLY, name="phase sets")
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
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
        self._thread = threading.Thread(target=self._run, name="phase-step-acquisition")
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            in_hand = _SetInHand(self._camera)
            try:
                frames = acquire_phase_steps(self._piezo, in_hand, self._axis, self._steps,
                                             calibration=self._calibration, settle_s=self._settle_s,
                                             timeout_s=self._timeout_s)
            except DeviceError as error:
                with self._count_lock:
                    self._lost_frames += in_hand.frames
                if not self._stop.is_set():
                    logger.warning("phase-step acquisition stopped: %s", error)
                    self._ring.close(error)
                return
            with self._count_lock:
                self._ring.put(frames, frame_id=self._sets)
            self._sets += 1

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
            self._thread.join(timeout=self._timeout_s * (len(self._steps) + 2) + 5.0)
            self._thread = None
        self._ring.close()
        try:
            self._camera.stop()
        except DeviceError as error:
            logger.info("camera stop: %s", error)
