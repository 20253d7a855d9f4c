"""The carrier-fringe interferometer's processor: one tilt-fringe frame per result.

The phase comes from the Fourier method (:func:`~wavestack.pipeline.carrier_phase`). The carrier
holds still from frame to frame: finding its peak costs ~5 ms of ~35 at 1024 x 1024, so it is
found on the first frame, after an aperture change or an invalid result, and every
``carrier_refresh_sets`` frames (1: every frame); a slow drift in between is tilt, which the fit
removes. The aperture is detected in the local fringe energy
(:func:`~wavestack.pipeline.phase.fringe_energy`), whose half-way level is the mirror's edge, with
the detection's levels taken beyond its background box, so the fit's pupil is the mirror's own
edge. The quality mask judges the sideband's modulation (where it is weak, the demodulated phase
is too), and a band one fringe period (:data:`RIM_PERIODS`) wide along the edge is left out of the
fit (marked rim): there the sideband filter, one period wide in space, mixes the outside in. On
the simulated 256 x 256 carrier station (30 x 18 fringes, period 7.3 px) the error against the
truth in the fitted subspace is 0.038 waves RMS with the band fitted, 0.016 without 2 px of it,
0.003 without 7 px.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..phase import carrier_phase, contrast_box, fringe_energy
from .fitter_source import FitterSource
from .interferometer import InterferometerProcessor, PhaseMaps
from .outcome import InterferometerOutcome
from .settings import InterferometerSettings

__all__ = ["RIM_PERIODS", "CarrierProcessor"]

#: The band along the aperture's edge left out of the fit, in fringe periods (module notes).
RIM_PERIODS = 0.5


class CarrierProcessor(InterferometerProcessor):
    """Single carrier frames to coefficients (see :class:`~.interferometer.InterferometerProcessor`).

    Takes the parameters of :class:`~.interferometer.InterferometerProcessor`, with
    ``settings.method = "carrier"``.

    Example
    -------
    >>> from wavestack.pipeline.instrument import FitSettings, SyncFitterSource
    >>> rows, cols = np.mgrid[:128, :128]
    >>> rho2 = ((rows - 63.5) ** 2 + (cols - 63.5) ** 2) / 50.0**2
    >>> frame = np.where(rho2 < 1, 120 + 80 * np.cos(2 * np.pi * cols / 8.0), 20).astype(np.uint8)
    >>> settings = InterferometerSettings(method="carrier", fit=FitSettings(method="circle", modes=6))
    >>> outcome = CarrierProcessor(settings, SyncFitterSource(settings.fit)).process([frame])
    >>> outcome.valid, [abs(round(f, 3)) for f in outcome.carrier], bool(abs(outcome.coefficients_waves[3]) < 0.01)
    (True, [0.125, 0.0], True)
    """

    METHOD = "carrier"

    def __init__(self, settings: InterferometerSettings, fitters: FitterSource, *,
                 mask: NDArray[np.bool_] | None = None, residual_map: bool = False) -> None:
        if settings.carrier_refresh_sets < 1:
            raise ValueError(f"carrier_refresh_sets: expected at least 1, got {settings.carrier_refresh_sets}")
        super().__init__(settings, fitters, mask=mask, residual_map=residual_map)
        self._carrier: tuple[float, float] | None = None  # sideband frequency, cycles/px, as carrier_phase takes it
        self._carrier_age = 0

    @property
    def frames_per_set(self) -> int:
        return 1

    def _check_set(self, frames: Sequence[NDArray[np.generic]]) -> None:
        if len(frames) != 1:
            raise ValueError(f"expected 1 frame(s) per set, got {len(frames)}")

    def _phase(self, frames: Sequence[NDArray[np.generic]]) -> PhaseMaps:
        s = self.settings
        frame = np.asarray(frames[0])
        known = self._carrier if self._carrier_age < s.carrier_refresh_sets else None
        result = carrier_phase(frame, sign=s.carrier_sign, carrier=known)
        if known is None:
            sign = s.carrier_sign
            self._carrier, self._carrier_age = (sign * result.carrier[0], sign * result.carrier[1]), 0
        self._carrier_age += 1
        period_px = 1.0 / float(np.hypot(*result.carrier))
        energy = fringe_energy(frame, period_px)
        # the background box's step residue reaches half a box out: the levels are taken beyond it
        margin = max(s.detection.edge_margin_px, contrast_box(period_px) // 2 + 3)
        detection = dataclasses.replace(s.detection, edge_margin_px=margin)
        carrier = (float(result.carrier[0]), float(result.carrier[1]))
        return PhaseMaps(result.phase, energy, result.modulation, detection, "carrier", carrier=carrier,
                         rim_px=int(round(RIM_PERIODS * period_px)))

    def _forget_state(self) -> None:
        super()._forget_state()
        self._carrier = None

    def _invalid(self, reason: str, **fields: object) -> InterferometerOutcome:
        """An invalid result; the next frame looks for its carrier afresh."""
        self._carrier = None
        return super()._invalid(reason, **fields)
