"""Where the station's sets of frames come from: a free-running camera, or piezo-stepped phase sets.

Both hand the pipeline the *newest* set and count what a slow pipeline skipped, so a slow stage
drops frames instead of building a backlog:

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
from dataclasses import dataclass

from wavestack.drivers.errors import DeviceError
from wavestack.drivers.frames import Frame
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration, acquire_phase_steps
from wavestack.drivers.ring import FrameRing, RingPolicy
from wavestack.drivers.u3v import U3VCamera

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SourceCounters:
    """Frames the camera produced, and frames given up anywhere before the pipeline."""

    acquired: int
    dropped: int


class CarrierSource:
    """Single carrier frames from a free-running camera."""

    frames_per_set = 1

    def __init__(self, camera: U3VCamera) -> None:
        self._camera = camera

    def start(self) -> None:
        self._camera.start()

    def read_set(self, timeout_s: float) -> tuple[Frame, ...]:
        """The newest frame, as a set of one."""
        return (self._camera.read_frame(timeout_s),)

    def counters(self) -> SourceCounters:
        c = self._camera.counters()
        return SourceCounters(c.acquired, c.dropped)

    def stop(self) -> None:
        self._camera.stop()


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

    @property
    def frames_per_set(self) -> int:
        return len(self._steps)

    def start(self) -> None:
        """Start the camera and the stepping thread (a fresh ring each time)."""
        self._camera.start()
        self._ring = FrameRing(self._capacity, RingPolicy.NEWEST_ONLY, name="phase sets")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="phase-step-acquisition")
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frames = acquire_phase_steps(self._piezo, self._camera, self._axis, self._steps,
                                             calibration=self._calibration, settle_s=self._settle_s,
                                             timeout_s=self._timeout_s)
            except DeviceError as error:
                if not self._stop.is_set():
                    logger.warning("phase-step acquisition stopped: %s", error)
                    self._ring.close(error)
                return
            self._ring.put(frames, frame_id=self._sets)
            self._sets += 1

    def read_set(self, timeout_s: float) -> tuple[Frame, ...]:
        """The newest complete set."""
        return self._ring.get(timeout_s)

    def counters(self) -> SourceCounters:
        camera = self._camera.counters()
        sets = self._ring.counters()
        return SourceCounters(camera.acquired, camera.dropped + sets.dropped * self.frames_per_set)

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
