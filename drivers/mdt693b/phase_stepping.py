"""Phase-shifting acquisition: step the piezo through phases and grab one frame per step.

The sequencing is device-agnostic: any phase shifter with ``limits``/``set_voltage`` (the
:class:`~wavestack.drivers.mdt693b.driver.MDT693B`) and any camera with
``trigger_software``/``read_frame`` will do. All step voltages are checked against the piezo's
limits before the first one is sent, so a sequence never stops half-way on a limit.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from wavestack.drivers.errors import LimitError
from wavestack.drivers.frames import Frame
from wavestack.drivers.mdt693b.driver import AxisLimits, VoltageReading

logger = logging.getLogger(__name__)


class AcquisitionCancelled(Exception):
    """The ``cancel`` event of :func:`acquire_phase_steps` was set: the set was given up, on purpose."""


@dataclass(frozen=True)
class PhaseStepCalibration:
    """Linear map from the interferometer phase to the piezo voltage.

    ``V(phi) = bias_v + volts_per_radian * phi``. For a reflective setup with wavelength
    ``lambda`` and a piezo of ``d`` nm per volt, the optical path changes twice the travel, so
    ``volts_per_radian = lambda / (4 pi d)`` (Malacara, *Optical Shop Testing*, 3rd ed., ch. 14).

    Attributes
    ----------
    volts_per_radian
        V per radian of phase; nonzero, finite.
    bias_v
        Voltage at zero phase, V (mid-range keeps steps of either sign inside the limits).
    """

    volts_per_radian: float
    bias_v: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.volts_per_radian) and self.volts_per_radian != 0.0):
            raise ValueError(f"volts_per_radian must be finite and nonzero, got {self.volts_per_radian!r}")
        if not math.isfinite(self.bias_v):
            raise ValueError(f"bias_v must be finite, got {self.bias_v!r}")

    def voltage_for(self, phase_rad: float) -> float:
        """Piezo voltage that produces ``phase_rad`` radians of phase, V."""
        return self.bias_v + self.volts_per_radian * phase_rad


@runtime_checkable
class TriggeredFrameSource(Protocol):
    """A camera that takes one frame per software trigger."""

    def trigger_software(self, timeout_s: float) -> None:
        """Start the exposure of one frame."""

    def read_frame(self, timeout_s: float) -> Frame:
        """The triggered frame; raises ``DeviceTimeout`` after ``timeout_s`` seconds."""


@runtime_checkable
class PhaseShifter(Protocol):
    """A piezo the phase-stepping sequence can drive (the MDT693B driver is one)."""

    @property
    def name(self) -> str:
        """Who this is in messages."""

    def limits(self, axis: str) -> AxisLimits:
        """Effective voltage limits of ``axis``."""

    def set_voltage(self, axis: str, volts: float, *, timeout_s: float, clamp: bool = False) -> VoltageReading:
        """Set and read back the output of ``axis``."""


def acquire_phase_steps(
    piezo: PhaseShifter,
    camera: TriggeredFrameSource,
    axis: str,
    steps_rad: Sequence[float],
    *,
    calibration: PhaseStepCalibration,
    settle_s: float,
    timeout_s: float,
    cancel: threading.Event | None = None,
) -> tuple[Frame, ...]:
    """Acquire one frame per phase step.

    For each step: set the piezo voltage (the driver reads it back), wait ``settle_s``, trigger the
    camera and read the frame.

    Parameters
    ----------
    piezo
        The phase shifter.
    camera
        The camera, already started.
    axis
        Piezo axis that moves the reference mirror.
    steps_rad
        Phase steps, radians, shape (n_steps,), e.g. ``(0, pi/2, pi, 3pi/2)``.
    calibration
        Phase-to-voltage map.
    settle_s
        Wait after each voltage change, s (piezo and mount settling).
    timeout_s
        Timeout of each device call, s.
    cancel
        When set (e.g. by a stop), the sequence gives up before its next step or during a settle
        wait, at once: a long ``settle_s`` never delays a stop.

    Returns
    -------
    tuple of Frame
        Length n_steps; copies of the camera frames whose metadata gain ``pzt_axis``,
        ``pzt_commanded_v``, ``pzt_readback_v`` and ``phase_step_rad``.

    Raises
    ------
    ValueError
        No steps, a non-finite step, or a negative ``settle_s`` / non-positive ``timeout_s``.
    LimitError
        A step's voltage lies outside ``piezo.limits(axis)``; nothing was sent.
    AcquisitionCancelled
        ``cancel`` was set.
    DeviceError
        Whatever the piezo or the camera raise during the sequence.
    """
    steps = tuple(float(step) for step in steps_rad)
    if not steps or not all(math.isfinite(step) for step in steps):
        raise ValueError(f"steps_rad must be a non-empty sequence of finite phases, got {steps_rad!r}")
    if not settle_s >= 0 or not timeout_s > 0:
        raise ValueError(f"expected settle_s >= 0 and timeout_s > 0, got {settle_s!r}, {timeout_s!r}")
    voltages = tuple(calibration.voltage_for(step) for step in steps)
    limits = piezo.limits(axis)
    outside = [(step, volts) for step, volts in zip(steps, voltages) if not limits.contains(volts)]
    if outside:
        listed = ", ".join(f"{step:.4g} rad -> {volts:.4g} V" for step, volts in outside)
        raise LimitError(piezo.name, f"phase steps outside the axis {axis} limits [{limits.min_v:g}, "
                         f"{limits.max_v:g}] V: {listed}; nothing sent")
    stop = cancel if cancel is not None else threading.Event()
    frames = []
    for step, volts in zip(steps, voltages):
        if stop.is_set():
            raise AcquisitionCancelled(f"{piezo.name}: phase-step set cancelled before step {step:.4g} rad")
        reading = piezo.set_voltage(axis, volts, timeout_s=timeout_s)
        if settle_s and stop.wait(settle_s):
            raise AcquisitionCancelled(f"{piezo.name}: phase-step set cancelled while settling at {volts:.4g} V")
        camera.trigger_software(timeout_s)
        frame = camera.read_frame(timeout_s)
        metadata = {**frame.metadata, "pzt_axis": axis, "pzt_commanded_v": reading.commanded_v,
                    "pzt_readback_v": reading.readback_v, "phase_step_rad": step}
        frames.append(dataclasses.replace(frame, metadata=metadata))
        logger.debug("phase step %.4f rad: %.2f V, frame %d", step, reading.readback_v, frame.frame_id)
    return tuple(frames)
