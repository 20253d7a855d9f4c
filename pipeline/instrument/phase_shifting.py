"""The phase-shifting interferometer's processor: a set of piezo-stepped frames per result.

The phase and modulation come from :func:`~wavestack.pipeline.phase_from_frames` (least squares
with known steps, the fixed four- and five-step formulas, or steps estimated from the data by
``aia`` or ``pca``); the modulation is both the aperture signal and what the quality mask judges.
Every other stage is :class:`~.interferometer.InterferometerProcessor`'s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..phase import check_fringe_modulation, phase_from_frames
from .interferometer import InterferometerProcessor, PhaseMaps
from .settings import InterferometerSettings

__all__ = ["PhaseShiftingProcessor"]

_GIVEN_STEPS = ("lsq", "aia")  # the algorithms that take the steps (aia: as its starting guess)


class PhaseShiftingProcessor(InterferometerProcessor):
    """Sets of phase-shifted frames to coefficients (see :class:`~.interferometer.InterferometerProcessor`).

    Takes the parameters of :class:`~.interferometer.InterferometerProcessor`, with
    ``settings.method = "psi"``.

    Example
    -------
    >>> from wavestack.pipeline.instrument import FitSettings, SyncFitterSource
    >>> rows, cols = np.mgrid[:96, :96]
    >>> rho2 = ((rows - 47.5) ** 2 + (cols - 47.5) ** 2) / 40.0**2
    >>> phi = 2 * np.pi * 0.3 * (2 * rho2 - 1)  # 0.3 (2 rho^2 - 1) waves: unit-RMS Noll Z4 = 0.3 / sqrt(3)
    >>> frames = [np.where(rho2 < 1, 100 + 80 * np.cos(phi + k * np.pi / 2), 10).astype(np.uint8) for k in range(4)]
    >>> settings = InterferometerSettings(psi_algorithm="four", fit=FitSettings(method="circle", modes=6))
    >>> outcome = PhaseShiftingProcessor(settings, SyncFitterSource(settings.fit)).process(frames)
    >>> outcome.valid, round(float(outcome.coefficients_waves[3]), 2)
    (True, 0.17)
    """

    METHOD = "psi"

    @property
    def frames_per_set(self) -> int | None:
        """Frames in a set (None: any number the algorithm takes)."""
        steps = self.settings.steps_rad
        return None if steps is None else len(steps)

    def _check_set(self, frames: Sequence[NDArray[np.generic]]) -> None:
        expected = self.frames_per_set
        if expected is not None and len(frames) != expected:
            raise ValueError(f"expected {expected} frame(s) per set, got {len(frames)}")

    def _phase(self, frames: Sequence[NDArray[np.generic]]) -> PhaseMaps:
        shapes = {np.shape(f) for f in frames}
        if len(shapes) > 1:  # a camera that changed its size within a set: invalid, not a fault
            raise ValueError(f"the frames of the set differ in shape: {sorted(shapes)}")
        s = self.settings
        steps = None
        if s.psi_algorithm in _GIVEN_STEPS:
            steps = (np.asarray(s.steps_rad, dtype=np.float64) if s.steps_rad is not None
                     else 2.0 * np.pi * np.arange(len(frames)) / len(frames))
        # a list, not a stack: the fast 4-step and Hariharan paths then copy nothing
        result = phase_from_frames(list(frames), method=s.psi_algorithm, steps=steps, direction=s.direction)
        return PhaseMaps(result.phase, result.modulation, result.modulation, s.detection, result.method,
                         steps_rad=np.asarray(result.steps))

    def _check_fringes(self, frames: Sequence[NDArray[np.generic]], phase: PhaseMaps) -> None:
        """Identical frames hold no phase (checked before a full detection only: it reads every frame)."""
        level = max(float(np.max(np.abs(np.asarray(f)))) for f in frames)
        check_fringe_modulation(phase.modulation, None, level)
