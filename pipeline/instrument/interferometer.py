"""One result from one set of interferograms: the stages every interferometer processor shares.

``process(frames) -> outcome``, one way, each stage a value:

1. **phase**: the subclass's (phase shifting, :mod:`.phase_shifting`; the carrier method,
   :mod:`.carrier`): the wrapped phase, the aperture signal and the modulation;
2. **aperture**: kept, or changed to, by :class:`~.tracking.ApertureKeeper` (watched every set,
   detected on a change, confirmed by the next set, the fitter asked of the :class:`FitterSource`);
   the set that first shows a change is reported invalid;
3. **unwrap**: on the fit grid (every ``fit_decimation``-th pixel), temporally against the previous
   set, spatially on the first, after an aperture change or when the residue check fails
   (:class:`~wavestack.pipeline.TemporalUnwrapper`);
4. **quality**: the per-pixel data-quality mask (:mod:`.quality`): marked pixels are NaN in the map;
   with ``settings.calibration`` the reference's error is subtracted from the map here (a set of
   another grid or aperture is an invalid result naming why, :mod:`~wavestack.pipeline.calibration`);
5. **fit**: the fitter of the aperture on the map (less a null test's wavefront), then spike
   clipping (:func:`~.statistics.clip_spikes`); a residual RMS above ``max_residual_waves`` makes
   the result invalid;
6. **statistics**: PV and PVr over the pixels used (:mod:`.statistics`).

The processor keeps its state explicit (the aperture keeper, the temporal unwrapper's previous
phase, a carrier processor's carrier) and knows nothing of devices, threads or the PLC: the
station, ``replay``, ``batch``, ``polish``, ``align`` and ``analyze`` (a stream of one set) all call
it, so the same frames give the same numbers whichever command reads them. A set is
:meth:`~InterferometerProcessor.prepare` (the stages that carry state from set to set), the fit,
and :meth:`~InterferometerProcessor.finish` (the outcome from the fit).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..aperture import DetectionSettings
from ..calibration import CalibrationRefused
from ..fit import FitResult, InvalidFrame
from ..phase import SpatialParams, TemporalUnwrapper
from .fitter_source import FitterChoice, FitterSource
from .outcome import InterferometerOutcome
from .quality import CLIPPED, PixelQuality, mark_quality
from .settings import InterferometerSettings
from .statistics import MapStatistics, clip_spikes, map_pv, robust_pv
from .tracking import AdoptedAperture, ApertureKeeper

__all__ = ["InterferometerProcessor", "PhaseMaps", "PreparedSet"]


@dataclass(frozen=True, eq=False)
class PhaseMaps:
    """What a processor's phase stage gives, at full resolution.

    Attributes
    ----------
    wrapped : ndarray
        Wrapped phase, radians.
    signal : ndarray
        The aperture signal (modulation, or a carrier frame's fringe energy).
    modulation : ndarray
        The fringe modulation the quality mask judges.
    detection : DetectionSettings
        How the aperture is detected in ``signal``.
    method : str
    steps_rad : ndarray or None
    carrier : (fx, fy) or None
    rim_px : int
        Width of the band along the aperture's edge this method cannot measure, pixels (left out
        of the fit; the carrier method's fringe period).
    """

    wrapped: NDArray[np.floating]
    signal: NDArray[np.floating]
    modulation: NDArray[np.floating]
    detection: DetectionSettings
    method: str
    steps_rad: NDArray[np.float64] | None = None
    carrier: tuple[float, float] | None = None
    rim_px: int = 0


@dataclass(frozen=True, eq=False)
class PreparedSet:
    """A set through phase, aperture, unwrap and quality, waiting for its fit (:meth:`InterferometerProcessor.prepare`).

    Attributes
    ----------
    outcome : InterferometerOutcome or None
        The set's outcome when it is invalid before any fit; None otherwise.
    to_fit : ndarray or None
        The map the fitter fits, waves on the fit grid (the measured map less a null), NaN where not used.
    waves : ndarray or None
        The measured map, waves on the fit grid, NaN where not used.
    flags : ndarray of uint8 or None
    choice : FitterChoice or None
        The fitter (sets sharing ``choice.fitter`` may be fitted in one batch).
    adopted : AdoptedAperture or None
    aperture_changed : bool
    unwrap_path : str or None
    phase : PhaseMaps or None
    timings_s : dict
        Seconds of the stages so far.
    choose_s : float
        Seconds spent choosing (or building) the fitter, counted in the fit stage.
    """

    outcome: InterferometerOutcome | None
    to_fit: NDArray[np.float64] | None = None
    waves: NDArray[np.float64] | None = None
    flags: NDArray[np.uint8] | None = None
    choice: FitterChoice | None = None
    adopted: AdoptedAperture | None = None
    aperture_changed: bool = False
    unwrap_path: str | None = None
    phase: PhaseMaps | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    choose_s: float = 0.0


class InterferometerProcessor:
    """Turns sets of interferograms into fitted coefficients, keeping state between sets (module notes).

    Not used directly: :class:`~.phase_shifting.PhaseShiftingProcessor` and
    :class:`~.carrier.CarrierProcessor` give the phase stage.

    Parameters
    ----------
    settings : InterferometerSettings
    fitters : FitterSource
        Builds (or hands out) the fitter of each aperture.
    mask : ndarray of bool, optional
        A user's aperture, full resolution (``settings.aperture`` is then not used).
    residual_map : bool
        Keep the residual map of a fit that spike clipping refitted (``analyze`` draws and saves
        it; one more pass over the fitter's operator). Its RMS and PV are given either way; the
        first fit's map is always kept.

    Raises
    ------
    ValueError
        ``settings.method`` is not the one the subclass measures (:attr:`METHOD`).
    """

    #: The ``settings.method`` this processor measures.
    METHOD = ""

    def __init__(self, settings: InterferometerSettings, fitters: FitterSource, *,
                 mask: NDArray[np.bool_] | None = None, residual_map: bool = False) -> None:
        if settings.method != self.METHOD:
            raise ValueError(f"method: {type(self).__name__} measures method {self.METHOD!r}, got {settings.method!r}")
        self.settings = settings
        self.fitters = fitters
        self._residual_map = residual_map
        self._keeper = ApertureKeeper(settings, fitters, mask)
        prefilter_px = settings.unwrap_prefilter_px / settings.fit_decimation  # full-resolution pixels
        self._unwrapper = TemporalUnwrapper(max_residues=settings.max_residues,
                                            params=SpatialParams(prefilter_sigma_px=prefilter_px))

    # ------------------------------------------------------------------ the subclass's stage
    def _check_set(self, frames: Sequence[NDArray[np.generic]]) -> None:
        """Raise ValueError for a set of the wrong length (a wiring error, not a measurement)."""
        raise NotImplementedError

    def _phase(self, frames: Sequence[NDArray[np.generic]]) -> PhaseMaps:
        raise NotImplementedError

    def _check_fringes(self, frames: Sequence[NDArray[np.generic]], phase: PhaseMaps) -> None:
        """Raise ValueError before a full detection when the set holds no fringes (default: nothing)."""

    def _forget_state(self) -> None:
        """Forget what a new aperture or an invalid result invalidates (the unwrapper; a subclass adds its own)."""
        self._unwrapper.reset()

    # ------------------------------------------------------------------ the stream
    def process(self, frames: Sequence[NDArray[np.generic]], *, fitter_method: str | None = None
                ) -> InterferometerOutcome:
        """Process one set: :meth:`prepare`, the fit, :meth:`finish`.

        Parameters
        ----------
        frames : sequence of ndarray, each (rows, cols)
            The set, in stepping order (one frame for the carrier method).
        fitter_method : str, optional
            Fit with a fitter of this method, built synchronously (replay reproducing the fitter
            that ran live, e.g. a ``qr`` stand-in).

        Returns
        -------
        InterferometerOutcome
            Invalid (with a reason) rather than raising for what a live stream can throw at it:
            no fringes, frames of different shapes (a camera resized within a set), an empty or
            unsupported aperture, a fit that cannot be done.

        Raises
        ------
        ValueError
            A set of the wrong length (a wiring error), or a user's mask of another shape than the
            frames.
        """
        prepared = self.prepare(frames, fitter_method=fitter_method)
        if prepared.outcome is not None:
            return prepared.outcome
        assert prepared.choice is not None and prepared.to_fit is not None
        tick = time.perf_counter()
        try:
            fit: FitResult | InvalidFrame = prepared.choice.fitter.fit(prepared.to_fit, nan_policy="omit",
                                                                       residual=True)
        except InvalidFrame as error:
            fit = error
        return self.finish(prepared, fit, time.perf_counter() - tick)

    def prepare(self, frames: Sequence[NDArray[np.generic]], *, fitter_method: str | None = None) -> PreparedSet:
        """The stages before the fit: phase, aperture, unwrap, quality, and the choice of fitter.

        Parameters and errors as for :meth:`process`. The state moves on as :meth:`process` moves
        it; the next set may be prepared before this one is finished, except with the carrier
        method, whose next set depends on this set's fit (an invalid fit makes the next frame look
        for its carrier afresh).

        Example
        -------
        One set through the split, as :meth:`process` runs it::

            prepared = processor.prepare(frames)
            fit = prepared.choice.fitter.fit(prepared.to_fit, nan_policy="omit", residual=True)
            outcome = processor.finish(prepared, fit, fit_s=0.0)
        """
        self._check_set(frames)
        timings: dict[str, float] = {}
        tick = time.perf_counter()
        try:
            phase = self._phase(frames)
        except ValueError as error:  # no fringes, no carrier, degenerate steps
            return PreparedSet(self._invalid(f"phase: {error}", timings_s=timings, error=error))
        timings["phase"] = time.perf_counter() - tick

        tick = time.perf_counter()
        keeper = self._keeper
        changed, problem = keeper.update(phase.signal, phase.modulation, phase.detection, fitter_method,
                                         rim_px=phase.rim_px, before_detection=lambda: self._check_fringes(frames, phase))
        if problem is not None:
            if keeper.adopted is None:
                self._forget_state()
            return PreparedSet(self._invalid(f"aperture: {problem}", timings_s=timings, error=problem,
                                             **self._extras(phase)))
        adopted = keeper.adopted
        assert adopted is not None
        if changed:
            self._forget_state()
        timings["aperture"] = time.perf_counter() - tick
        return self._unwrapped(frames, phase, adopted, changed, fitter_method, timings)

    def _unwrapped(self, frames: Sequence[NDArray[np.generic]], phase: PhaseMaps, adopted: AdoptedAperture,
                   changed: bool, fitter_method: str | None, timings: dict[str, float]) -> PreparedSet:
        """Unwrap, quality and the fitter of a set on its aperture."""
        step = self.settings.fit_decimation
        tick = time.perf_counter()
        unwrapped = self._unwrapper.update(np.ascontiguousarray(phase.wrapped[::step, ::step]), adopted.fitted)
        timings["unwrap"] = time.perf_counter() - tick

        tick = time.perf_counter()
        quality = mark_quality(unwrapped.phase, phase.modulation, frames, step, adopted.marks, adopted.components,
                               self.settings.quality)
        waves = quality.waves
        calibration = self.settings.calibration
        if calibration is not None:  # the reference's error, measured and removed
            try:
                calibration.check_measurement(frames[0].shape)
                waves = waves - calibration.correction(adopted.fitted, step)
            except CalibrationRefused as error:
                return PreparedSet(self._invalid(f"calibration: {error}", timings_s=timings, error=error,
                                                 **self._extras(phase)))
        to_fit = waves if adopted.null_waves is None else waves - adopted.null_waves
        timings["quality"] = time.perf_counter() - tick

        tick = time.perf_counter()
        choice = self.fitters.current()
        assert choice is not None
        if fitter_method is not None and choice.kind != fitter_method:
            choice = self.fitters.use_method(fitter_method)
        return PreparedSet(None, to_fit, waves, quality.flags, choice, adopted, changed, unwrapped.path, phase,
                           timings, choose_s=time.perf_counter() - tick)

    def finish(self, prepared: PreparedSet, fit: FitResult | InvalidFrame, fit_s: float) -> InterferometerOutcome:
        """The outcome of a prepared set from its fit (or the fit's refusal): clipping, limits, statistics.

        Parameters
        ----------
        prepared : PreparedSet
            From :meth:`prepare` of this processor, with nothing to fit when ``prepared.outcome`` is set.
        fit : FitResult or InvalidFrame
            ``prepared.choice.fitter``'s fit of ``prepared.to_fit`` (``nan_policy="omit"``,
            ``residual=True``), alone or in a batch; the error when it refused.
        fit_s : float
            Seconds the fit took (a batch's share), for ``timings_s["fit"]``.

        Returns
        -------
        InterferometerOutcome
            Invalid when the fit was refused or its residual RMS exceeds ``max_residual_waves``.
        """
        if prepared.outcome is not None:
            return prepared.outcome
        assert prepared.choice is not None and prepared.to_fit is not None and prepared.flags is not None
        timings = dict(prepared.timings_s)
        timings["fit"] = prepared.choose_s + fit_s
        timings["clip"] = 0.0
        if not isinstance(fit, InvalidFrame) and self.settings.clip_sigma is not None:
            tick = time.perf_counter()
            try:
                fit, clipped = clip_spikes(prepared.choice.fitter, prepared.to_fit, prepared.flags, fit,
                                           self.settings.clip_sigma, residual=self._residual_map)
            except InvalidFrame as error:
                fit, clipped = error, 0
            if clipped and prepared.waves is not prepared.to_fit:
                assert prepared.waves is not None
                prepared.waves[(prepared.flags & CLIPPED) != 0] = np.nan
            timings["clip"] = time.perf_counter() - tick
        context = self._context(prepared, timings)
        if isinstance(fit, InvalidFrame):
            return self._invalid(f"fit: {fit}", error=fit, **context)
        limit = self.settings.max_residual_waves
        if limit is not None and not fit.residual_rms <= limit:  # unwrapping errors, a bad frame
            return self._invalid(f"fit: residual {fit.residual_rms:.3g} waves rms exceeds "
                                 f"max_residual_waves = {limit:g}", **context)
        tick = time.perf_counter()
        assert fit.residual_pv is not None and prepared.adopted is not None  # asked for
        statistics = MapStatistics(fit.residual_rms, fit.residual_pv, map_pv(prepared.to_fit, fit.removed),
                                   robust_pv(prepared.adopted.pvr, prepared.to_fit))
        timings["statistics"] = time.perf_counter() - tick
        return InterferometerOutcome(True, None, fit.coefficients, fit, statistics=statistics, **context)

    # ------------------------------------------------------------------ values
    def _context(self, prepared: PreparedSet, timings: dict[str, float]) -> dict[str, object]:
        """The outcome's fields a prepared set fixes."""
        adopted = prepared.adopted
        assert adopted is not None and prepared.flags is not None
        return dict(choice=prepared.choice, aperture=adopted.aperture, aperture_changed=prepared.aperture_changed,
                    unwrap_path=prepared.unwrap_path, waves=prepared.waves, flags=prepared.flags,
                    quality=PixelQuality.of(prepared.flags), timings_s=timings, aperture_choice=adopted.choice,
                    edge=adopted.edge, calibration=self._calibration_digest(), **self._extras(prepared.phase))

    def _calibration_digest(self) -> str | None:
        calibration = self.settings.calibration
        return None if calibration is None else calibration.digest

    @staticmethod
    def _extras(phase: PhaseMaps | None) -> dict[str, object]:
        if phase is None:
            return {}
        return dict(method=phase.method, steps_rad=phase.steps_rad, carrier=phase.carrier)

    def _invalid(self, reason: str, **fields: object) -> InterferometerOutcome:
        """An invalid result (a subclass may forget state on it)."""
        return InterferometerOutcome(False, reason, **fields)  # type: ignore[arg-type]
