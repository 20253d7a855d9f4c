"""One result from one set of frames: phase, aperture, unwrapping, fit — the station's hot path.

The stages are the signal path's (``wavestack.pipeline``'s measurement) arranged for a stream:

1. **phase** — temporal phase shifting of a set, or the carrier method on one frame; the
   modulation (or local fringe contrast) comes with it;
2. **aperture** — an :class:`~wavestack.pipeline.ApertureWatch` checks each
   frame cheaply against the current aperture; only when it reports a change does the full
   detection run, and only when the next set confirms a change is a new fitter built (the rule is
   :mod:`~wavestack.station.aperture_confirmation`'s table; the fitters
   :class:`~wavestack.station.fitter_cache.FitterCache`'s); the set that shows the change first is
   reported invalid, since its frames may straddle the moment the optic moved;
3. **unwrap** — on the fit's grid (below), temporally against the previous result, spatially on the
   first frame, after an aperture change or when the residue check fails
   (:class:`~wavestack.pipeline.TemporalUnwrapper`);
4. **fit** — on every ``fit_decimation``-th pixel in each direction. Thirty-six Zernike terms
   are determined many times over by a quarter of a megapixel map, and decimating by 2 cuts both
   the refit and, more importantly, the fitter build on an aperture change by four. The fit's
   residual RMS comes with it; its peak-to-valley (``fit(..., residual=True)``) costs one more
   pass over the fitter's operator, in the operator's float32, and is timed with the fit.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.config import ProcessingSettings
from wavestack.pipeline import Aperture
from wavestack.pipeline import EmptyAperture, UnsupportedAperture
from wavestack.pipeline import DetectionSettings, compare_apertures, detect_aperture
from wavestack.pipeline import ApertureWatch
from wavestack.pipeline import carrier_phase
from wavestack.pipeline import FitResult, InvalidFrame
from wavestack.pipeline import local_fringe_contrast
from wavestack.pipeline import phase_from_frames
from wavestack.pipeline import SpatialParams, TemporalUnwrapper
from wavestack.station.aperture_confirmation import (
    ApertureAction,
    ApertureEvent,
    AperturePhase,
    ApertureState,
    Detection,
    confirm,
)
from wavestack.station.fitter_cache import FitterCache, FitterChoice
from wavestack.station.results import ApertureRecord, FitDiagnostics

logger = logging.getLogger(__name__)

#: The carrier method re-finds the carrier peak at least this often (sets).
CARRIER_REFRESH_SETS = 32


@dataclass(frozen=True, eq=False)
class InterferometerOutcome:
    """What one set of frames gave.

    Attributes
    ----------
    valid : bool
        False when no trustworthy coefficients came out; ``reason`` says why.
    reason : str or None
    coefficients_waves : ndarray, shape (modes,) or None
        Zernike coefficients of the wavefront in waves, the fitter's ordering and normalisation.
    fit : FitResult or None
    choice : FitterChoice or None
        The fitter used (kind, fallback flag, aperture id).
    aperture : Aperture or None
        Full-resolution aperture of this set.
    aperture_changed : bool
        True when this set started a new aperture (a new fitter).
    unwrap_path : str or None
        "spatial" or "temporal".
    waves : ndarray, shape (rows, cols) decimated by ``fit_decimation``, or None
        Unwrapped wavefront on the fit's grid, waves, NaN outside the aperture.
    residual_pv : float
        Peak-to-valley of the fit residual on the fit's grid, waves (NaN when invalid).
    timings_s : dict
        Seconds per stage: phase, aperture, unwrap, fit.
    """

    valid: bool
    reason: str | None
    coefficients_waves: NDArray[np.float64] | None = None
    fit: FitResult | None = None
    choice: FitterChoice | None = None
    aperture: Aperture | None = None
    aperture_changed: bool = False
    unwrap_path: str | None = None
    waves: NDArray[np.float64] | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    residual_pv: float = float("nan")

    # -- what the result records (pure views of the fields above)
    @property
    def fitter_kind(self) -> str | None:
        return self.choice.kind if self.choice is not None else None

    @property
    def fitter_fallback(self) -> bool:
        return bool(self.choice and self.choice.fallback)

    @property
    def residual_rms(self) -> float:
        return self.fit.residual_rms if self.fit is not None else float("nan")

    @property
    def normalisation(self) -> str:
        return self.fit.basis.normalisation if self.fit is not None else "rms"

    @property
    def diagnostics(self) -> FitDiagnostics | None:
        if self.choice is None:
            return None
        d = self.choice.fitter.diagnostics
        return FitDiagnostics(gram_condition=d.gram_condition, flips=d.flips, max_beltrami=d.max_beltrami)

    @property
    def aperture_record(self) -> ApertureRecord | None:
        if self.aperture is None:
            return None
        return ApertureRecord(id=self.choice.aperture_id if self.choice else None, changed=self.aperture_changed,
                              topology=self.aperture.describe(), components=self.aperture.components,
                              valid_pixels=int(self.aperture.mask.sum()))

    @property
    def new_aperture_mask(self) -> NDArray[np.bool_] | None:
        """The full-resolution mask when this set started a new aperture (for the recording)."""
        return self.aperture.mask if self.aperture_changed and self.aperture is not None else None


@dataclass(frozen=True, eq=False)
class PreparedSet:
    """A set through phase, aperture and unwrap, waiting for its fit (:meth:`SetProcessor.prepare`).

    Attributes
    ----------
    outcome : InterferometerOutcome or None
        The set's outcome when it is invalid before any fit (phase, aperture); None otherwise.
    waves : ndarray, shape (rows, cols) decimated by ``fit_decimation``, or None
        The unwrapped map to fit, waves (float32), NaN outside the aperture.
    choice : FitterChoice or None
        The fitter to fit it with (sets sharing ``choice.fitter`` may be fitted in one batch).
    aperture : Aperture or None
    aperture_changed : bool
    unwrap_path : str or None
    timings_s : dict
        Seconds of the phase, aperture and unwrap stages.
    choose_s : float
        Seconds spent choosing (or building) the fitter, counted in the fit stage.
    """

    outcome: InterferometerOutcome | None
    waves: NDArray[np.float32] | None = None
    choice: FitterChoice | None = None
    aperture: Aperture | None = None
    aperture_changed: bool = False
    unwrap_path: str | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    choose_s: float = 0.0


class SetProcessor:
    """Turns sets of frames into fitted coefficients, keeping state between sets.

    Parameters
    ----------
    settings : ProcessingSettings
    detection : DetectionSettings
        Aperture detection for the full pass.
    background_builds : bool
        Build the configured fitter off the result path (station) or synchronously (replay).
    """

    def __init__(self, settings: ProcessingSettings, detection: DetectionSettings = DetectionSettings(), *,
                 background_builds: bool = True) -> None:
        self.settings = settings
        self._detection = detection
        self._steps_rad = np.radians(np.asarray(settings.steps_deg, dtype=np.float64))
        self._apertures = ApertureState()  # the aperture in use, one waiting for confirmation, the watch
        self._carrier: tuple[float, float] | None = None  # sideband frequency, cycles/px (carrier method)
        self._carrier_age = 0
        # unwrapped on the fit's grid (every fit_decimation-th pixel): the fit sees nothing else, and
        # the spatial unwrap after an aperture change costs a quarter (0.4 s -> 0.08 s at 1024 x 1024)
        prefilter_px = settings.unwrap_prefilter_px / settings.fit_decimation  # full-resolution pixels
        self._unwrapper = TemporalUnwrapper(max_residues=settings.max_residues,
                                            params=SpatialParams(prefilter_sigma_px=prefilter_px))
        self.fitters = FitterCache(settings.fit_settings(), background=background_builds)

    def close(self) -> None:
        """Stop the background fitter builds."""
        self.fitters.close()

    def process(self, frames: Sequence[NDArray[np.generic]], *,
                fitter_method: str | None = None) -> InterferometerOutcome:
        """Process one set (psi) or one frame (carrier): :meth:`prepare`, the fit, :meth:`finish`.

        Parameters
        ----------
        frames : sequence of ndarray, each (rows, cols)
            ``settings.frames_per_set`` frames, in stepping order.
        fitter_method : str, optional
            Fit with a fitter of this method, built synchronously (replay reproducing the fitter
            that ran live, e.g. a ``qr`` stand-in).

        Returns
        -------
        InterferometerOutcome
            Invalid (with a reason) rather than raising for what a live stream can throw at it:
            an empty or unsupported aperture, frames without fringes, a fit that cannot be done.

        Raises
        ------
        ValueError
            A set of the wrong length or of frames of different shapes (a wiring error).
        """
        prepared = self.prepare(frames, fitter_method=fitter_method)
        if prepared.outcome is not None:
            return prepared.outcome
        assert prepared.choice is not None and prepared.waves is not None
        tick = time.perf_counter()
        try:
            fit: FitResult | InvalidFrame = prepared.choice.fitter.fit(prepared.waves, nan_policy="omit", residual=True)
        except InvalidFrame as error:
            fit = error
        return self.finish(prepared, fit, time.perf_counter() - tick)

    def prepare(self, frames: Sequence[NDArray[np.generic]], *, fitter_method: str | None = None) -> PreparedSet:
        """The stages before the fit: phase, aperture, unwrap, and the choice of fitter.

        Parameters and errors as for :meth:`process`. The processor's state (aperture, unwrapper,
        carrier) moves on as :meth:`process` moves it; the next set may be prepared before this one
        is finished, except with the carrier method, whose next set depends on this set's fit (an
        invalid fit makes the next frame look for its carrier afresh).

        Returns
        -------
        PreparedSet
            ``outcome`` set when the set is invalid already (nothing to fit); else the map to fit.

        Example
        -------
        One set through the split, as :meth:`process` runs it::

            prepared = processor.prepare(frames)
            fit = prepared.choice.fitter.fit(prepared.waves, nan_policy="omit", residual=True)
            outcome = processor.finish(prepared, fit, fit_s=0.0)
        """
        expected = self.settings.frames_per_set
        if len(frames) != expected:
            raise ValueError(f"expected {expected} frame(s) per set, got {len(frames)}")
        timings: dict[str, float] = {}
        tick = time.perf_counter()
        try:
            wrapped, signal, erode_px = self._phase(frames)
        except ValueError as error:  # no fringes, no carrier, degenerate steps
            return PreparedSet(self._invalid(f"phase: {error}", timings_s=timings))
        timings["phase"] = time.perf_counter() - tick

        tick = time.perf_counter()
        changed, problem = self._update_aperture(signal, erode_px, fitter_method)
        if problem is not None:
            return PreparedSet(self._invalid(f"aperture: {problem}", timings_s=timings))
        aperture = self._apertures.current
        assert aperture is not None
        timings["aperture"] = time.perf_counter() - tick

        tick = time.perf_counter()
        step = self.settings.fit_decimation
        unwrapped = self._unwrapper.update(np.ascontiguousarray(wrapped[::step, ::step]),
                                           np.ascontiguousarray(aperture.mask[::step, ::step]))
        waves = unwrapped.phase / (2.0 * np.pi)  # radians to waves, kept float32 on the fit grid
        timings["unwrap"] = time.perf_counter() - tick

        tick = time.perf_counter()
        choice = self.fitters.current()
        assert choice is not None
        if fitter_method is not None and choice.kind != fitter_method:
            choice = self.fitters.use_method(fitter_method)
        return PreparedSet(None, waves, choice, aperture, changed, unwrapped.path, timings,
                           choose_s=time.perf_counter() - tick)

    def finish(self, prepared: PreparedSet, fit: FitResult | InvalidFrame, fit_s: float) -> InterferometerOutcome:
        """The outcome of a prepared set from its fit (or the fit's refusal).

        Parameters
        ----------
        prepared : PreparedSet
            From :meth:`prepare` of this processor, with nothing to fit when ``prepared.outcome`` is set.
        fit : FitResult or InvalidFrame
            ``prepared.choice.fitter``'s fit of ``prepared.waves`` (``nan_policy="omit"``,
            ``residual=True``), alone or in a batch (``Fitter.fit_many``); the error when it refused.
        fit_s : float
            Seconds the fit took (a batch's share), for ``timings_s["fit"]``.

        Returns
        -------
        InterferometerOutcome
            Invalid when the fit was refused or its residual exceeds ``max_residual_waves``.
        """
        if prepared.outcome is not None:
            return prepared.outcome
        timings = dict(prepared.timings_s)
        context = dict(choice=prepared.choice, aperture=prepared.aperture, aperture_changed=prepared.aperture_changed,
                       unwrap_path=prepared.unwrap_path, timings_s=timings)
        if isinstance(fit, InvalidFrame):
            return self._invalid(f"fit: {fit}", **context)
        timings["fit"] = prepared.choose_s + fit_s
        if not fit.residual_rms <= self.settings.max_residual_waves:  # unwrapping errors, a bad frame
            return self._invalid(f"fit: residual {fit.residual_rms:.3g} waves rms exceeds "
                                 f"max_residual_waves = {self.settings.max_residual_waves:g}", **context)
        assert fit.residual_pv is not None  # asked for above
        return InterferometerOutcome(True, None, fit.coefficients, fit, prepared.choice, prepared.aperture,
                                     prepared.aperture_changed, prepared.unwrap_path, prepared.waves, timings,
                                     fit.residual_pv)

    def fit_map(self, waves: NDArray[np.float64], choice: FitterChoice) -> FitResult:
        """Fit a full-resolution map with a given fitter (the simulator's truth, for comparison)."""
        step = self.settings.fit_decimation
        return choice.fitter.fit(np.asarray(waves)[::step, ::step], nan_policy="omit")

    # ------------------------------------------------------------------ stages

    def _phase(self, frames: Sequence[NDArray[np.generic]]) -> tuple[NDArray[np.float64], NDArray, int]:
        s = self.settings
        if s.method == "psi":
            steps = self._steps_rad if s.psi_algorithm in ("lsq", "aia") else None
            # a list, not a stack: the fast 4-step and Hariharan paths then copy nothing
            result = phase_from_frames(list(frames), method=s.psi_algorithm, steps=steps)
            return result.phase, result.modulation, 0
        # The carrier (the bench's tilt fringes) holds still from frame to frame: finding its peak
        # in the spectrum costs ~5 ms of ~35 at 1024 x 1024, so it is found on the first frame,
        # after an aperture change or an invalid result, and every CARRIER_REFRESH_SETS sets;
        # a slow drift in between is tilt, which the fit removes.
        known = self._carrier if self._carrier_age < CARRIER_REFRESH_SETS else None
        result = carrier_phase(np.asarray(frames[0]), sign=s.carrier_sign, carrier=known)
        if known is None:
            sign = s.carrier_sign
            self._carrier, self._carrier_age = (sign * result.carrier[0], sign * result.carrier[1]), 0
        self._carrier_age += 1
        period_px = 1.0 / float(np.hypot(*result.carrier))
        # the sideband modulation misses where aberration moves the local fringe frequency; the
        # local contrast does not (see pipeline.measurement.local_fringe_contrast)
        contrast = local_fringe_contrast(np.asarray(frames[0], dtype=np.float32), period_px)
        return result.phase, contrast, int(round(period_px))

    def _update_aperture(self, signal: NDArray, erode_px: int, fitter_method: str | None) -> tuple[bool, str | None]:
        """Keep, or change to, the aperture this set shows (see :mod:`~wavestack.station.aperture_confirmation`).

        Returns
        -------
        (changed, problem)
            ``changed``: a new aperture starts here; ``problem``: why this set is invalid (a change
            waiting for the next set to confirm it, or a failed detection), else None.
        """
        state = self._apertures
        if state.watch is not None and not state.watch.check(signal).changed:
            self._apertures, _ = confirm(state, ApertureEvent.QUIET)
            return False, None
        try:
            return self._detect(signal, erode_px, fitter_method)
        except (EmptyAperture, UnsupportedAperture, ValueError) as error:
            self._apertures, _ = confirm(self._apertures, ApertureEvent.FAILED)
            self._forget_aperture()
            return False, str(error)

    def _detect(self, signal: NDArray, erode_px: int, fitter_method: str | None) -> tuple[bool, str | None]:
        """The full detection, classified and confirmed; a new fitter when the aperture is adopted."""
        state = self._apertures
        detected = detect_aperture(signal, self._detection)
        aperture = detected.aperture.eroded(erode_px)  # the contrast box spreads the edge outward by half a box
        watch = ApertureWatch(detected.aperture.mask, detected.threshold, factor=self.settings.watch_block_px)
        event, difference = self._classify(state, aperture)
        self._apertures, action = confirm(state, event, Detection(aperture, watch))
        if action is ApertureAction.CONFIRMING:
            return False, f"aperture changed ({difference}); confirming on the next set"
        if action is ApertureAction.KEEP:
            return False, None
        if state.current is not None:
            logger.info("aperture changed (%s): %s", difference, aperture.describe())
        step = self.settings.fit_decimation
        fit_aperture = aperture if step == 1 else Aperture.from_mask(aperture.mask[::step, ::step])
        self.fitters.new_aperture(fit_aperture, method=fitter_method)
        self._carrier = None
        self._unwrapper.reset()
        return True, None

    def _classify(self, state: ApertureState, aperture: Aperture) -> tuple[ApertureEvent, str | None]:
        """What a full detection shows against the aperture in use and the pending one."""
        if state.current is None:
            return ApertureEvent.NEW, None
        difference = self._difference(state.current, aperture)
        if difference is None:
            return ApertureEvent.SAME, None
        if state.phase is AperturePhase.PENDING and state.pending is not None \
                and self._difference(state.pending, aperture) is None:
            return ApertureEvent.AS_PENDING, difference
        return ApertureEvent.NEW, difference

    def _difference(self, reference: Aperture, aperture: Aperture) -> str | None:
        """Why two apertures are not the same one (None when they are)."""
        change = compare_apertures(reference, aperture, self.settings.iou_threshold)
        return change.reason if change.changed else None

    def _invalid(self, reason: str, **fields: object) -> InterferometerOutcome:
        """An invalid result; the next carrier frame looks for its carrier afresh."""
        self._carrier = None
        return InterferometerOutcome(False, reason, **fields)  # type: ignore[arg-type]

    def _forget_aperture(self) -> None:
        self._carrier = None
        self._unwrapper.reset()
