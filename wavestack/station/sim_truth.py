"""The truth comparison of a simulated station: measured coefficients against the simulator's truth.

Built by :func:`wavestack.station.devices.open_station_devices` for a simulated camera only (it
is the one station module beside ``devices`` that knows simulator types); the loop sees it as a
:class:`~wavestack.station.truth.TruthCheck`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.frames import Frame
from wavestack.pipeline import InvalidFrame
from wavestack.pipeline.instrument import SlopeOutcome
from wavestack.simulators.bench import FrameTruth, SimulatedInterferometer, SimulatedShackHartmann
from wavestack.simulators.spots import SpotTruth
from wavestack.pipeline.instrument import FitterChoice, InterferometerOutcome
from wavestack.station.results import TruthErrors
from wavestack.station.truth import coefficient_errors

logger = logging.getLogger(__name__)

#: The true coefficients' line is re-anchored at a frame this far (s) from its anchor: the fits are
#: float32, so the slope carries ~1e-6 relative rounding that the extrapolation multiplies.
_REANCHOR_S = 10.0


def _frame_truth(bench: SimulatedInterferometer | SimulatedShackHartmann, frame: Frame) -> object | None:
    try:
        return bench.camera.truth(frame.frame_id)
    except KeyError:
        return None


@dataclass(eq=False)
class InterferometerTruthCheck:
    """Truth errors of an interferometer's fits, in the fitted subspace over the fitted aperture.

    Parameters
    ----------
    bench : SimulatedInterferometer
    fit_decimation : int
        The processor fits every n-th pixel in each direction; the truth map is fitted alike.
    """

    bench: SimulatedInterferometer
    fit_decimation: int
    _key: tuple[int, int, bool] | None = field(default=None, init=False)  # (fitter, aperture revision, calibrated)
    _line: tuple[float, NDArray, NDArray] = field(default=(0.0, np.zeros(0), np.zeros(0)), init=False)

    def capture(self, frame: Frame) -> object | None:
        return _frame_truth(self.bench, frame)

    def compare(self, truth: object | None, outcome: object) -> TruthErrors | None:
        """RMS of the true wavefront and of measured minus true (None without a valid fit or a truth)."""
        if not isinstance(truth, FrameTruth) or not isinstance(outcome, InterferometerOutcome) or not outcome.valid:
            return None
        if outcome.choice is None or outcome.fit is None:
            return TruthErrors(None, None)
        if truth.source.aperture_revision != truth.aperture_revision:
            return TruthErrors(None, None)  # the optic's aperture changed after this frame: its truth is gone
        try:
            true_coefficients = self._true_coefficients(truth, outcome.choice, outcome.calibration is not None)
        except InvalidFrame as error:  # the optic's aperture changed within the set: nothing to compare
            logger.debug("no truth comparison: %s", error)
            return TruthErrors(None, None)
        fitter = outcome.choice.fitter
        # RMS over the fitted samples from the orthonormal form (no pass over the operator)
        return TruthErrors(fitter.surface_rms(true_coefficients),
                           fitter.surface_rms(outcome.fit.coefficients - true_coefficients))

    def _true_coefficients(self, truth: FrameTruth, choice: FitterChoice, calibrated: bool) -> NDArray:
        """The simulator's true coefficients in this fitter's basis at the frame's time, ``a + (t - t0) b``.

        ``calibrated``: the map had the reference's error removed, so the truth is the part alone
        (the optic's wavefront less its reference's error).

        The simulated optic drifts linearly in time and the fit is linear in the map, so the true
        coefficients at any frame time follow from two fits per fitter and aperture revision (at
        t0 and t0 + 1 s) instead of one fit of a freshly rendered 8 MB map per result. The anchor
        t0 is the first frame compared, renewed every ``_REANCHOR_S``: anchored at t = 0, the
        float32 slope's rounding grew with the device clock (1.3e-6 to 1.9e-6 waves at 4-9 s).
        Each anchor map is rendered on the fitted grid only (every ``fit_decimation``-th pixel,
        :meth:`~wavestack.simulators.optic.TestOptic.wavefront`), the values the fit of the full
        map's slice used: the same coefficients, a quarter of the memory at decimation 2.
        """
        key = (id(choice.fitter), truth.aperture_revision, calibrated)
        if self._key != key or abs(truth.time_s - self._line[0]) > _REANCHOR_S:
            t0 = truth.time_s
            step = self.fit_decimation
            reference = truth.source.truth(t0).reference_waves if calibrated else None
            less = 0.0 if reference is None else reference[::step, ::step]
            start = self._fit(truth.source.wavefront(t0, step) - less, choice)
            later = self._fit(truth.source.wavefront(t0 + 1.0, step) - less, choice)
            self._key, self._line = key, (t0, start, later - start)
        t0, start, per_second = self._line
        return start + (truth.time_s - t0) * per_second

    @staticmethod
    def _fit(waves: NDArray[np.float64], choice: FitterChoice) -> NDArray[np.float64]:
        return choice.fitter.fit(waves, nan_policy="omit").coefficients


@dataclass(eq=False)
class ShackHartmannTruthCheck:
    """Truth errors of a Shack-Hartmann reconstruction, from the coefficients.

    Both in the unit-RMS circle basis over the pupil disk, Noll 4 onwards
    (:func:`~wavestack.station.truth.coefficient_errors`).
    """

    bench: SimulatedShackHartmann

    def capture(self, frame: Frame) -> object | None:
        return _frame_truth(self.bench, frame)

    def compare(self, truth: object | None, outcome: object) -> TruthErrors | None:
        if not isinstance(truth, SpotTruth) or not isinstance(outcome, SlopeOutcome) or not outcome.valid:
            return None
        if outcome.coefficients_waves is None:
            return TruthErrors(None, None)
        return TruthErrors(*coefficient_errors(outcome.coefficients_waves, truth.coefficients_waves))
