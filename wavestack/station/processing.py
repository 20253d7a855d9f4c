"""One result from one set of frames: phase, aperture, unwrapping, fit — the station's hot path.

The stages are the signal path's (:mod:`wavestack.pipeline.measurement`) arranged for a stream:

1. **phase** — temporal phase shifting of a set, or the carrier method on one frame; the
   modulation (or local fringe contrast) comes with it;
2. **aperture** — an :class:`~wavestack.pipeline.aperture_watch.ApertureWatch` checks each
   frame cheaply against the current aperture; only when it reports a change does the full
   detection run, and only when the next set confirms a change is a new fitter built (see
   :class:`~wavestack.station.fitter_cache.FitterCache`); the set that shows the change first is
   reported invalid, since its frames may straddle the moment the optic moved;
3. **unwrap** — on the fit's grid (below), temporally against the previous result, spatially on the
   first frame, after an aperture change or when the residue check fails
   (:class:`~wavestack.pipeline.unwrap.TemporalUnwrapper`);
4. **fit** — on every ``fit_decimation``-th pixel in each direction. Thirty-six Zernike terms
   are determined many times over by a quarter of a megapixel map, and decimating by 2 cuts both
   the refit and, more importantly, the fitter build on an aperture change by four.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from wavestack.config import setting
from wavestack.pipeline import Aperture
from wavestack.pipeline import EmptyAperture, UnsupportedAperture
from wavestack.pipeline import DetectionSettings, compare_apertures, detect_aperture
from wavestack.pipeline import ApertureWatch
from wavestack.pipeline import carrier_phase
from wavestack.pipeline import FitResult, InvalidFrame
from wavestack.pipeline import local_fringe_contrast
from wavestack.pipeline import phase_from_frames
from wavestack.pipeline import SpatialParams, TemporalUnwrapper
from wavestack.station.fitter_cache import FitSettings, FitterCache, FitterChoice

if TYPE_CHECKING:
    from wavestack.station.sh_processing import LensletSlopes

logger = logging.getLogger(__name__)

#: The carrier method re-finds the carrier peak at least this often (sets).
CARRIER_REFRESH_SETS = 32


class _ApertureUnconfirmed(Exception):
    """This set's aperture differs from the current one; the next set must confirm it."""


@dataclass(frozen=True)
class ProcessingSettings:
    """How frames become coefficients (the ``[processing]`` table of a station config)."""

    method: Literal["psi", "carrier"] = setting("psi", doc="phase-shifted sets or single carrier frames")
    psi_algorithm: Literal["lsq", "four", "hariharan", "aia", "pca"] = "lsq"
    steps_deg: tuple[float, ...] = setting((0.0, 90.0, 180.0, 270.0), minimum=-720.0, maximum=720.0,
                                           doc="phase steps of a set, degrees")
    carrier_sign: Literal[1, -1] = 1
    modes: int = setting(36, minimum=3, maximum=231)
    ordering: Literal["noll", "ansi", "fringe"] = "noll"
    fit_method: Literal["csf-qcm", "conformal", "qr", "circle"] = "csf-qcm"
    remove: Literal["ptt", "pttp", "none"] = "ptt"
    fit_decimation: int = setting(2, minimum=1, maximum=8, doc="fit every n-th pixel in each direction")
    iou_threshold: float = setting(0.98, minimum=0.5, maximum=1.0)
    watch_block_px: int = setting(4, minimum=1, maximum=32)
    max_residues: int = setting(0, minimum=0)
    unwrap_prefilter_px: float = setting(1.5, minimum=0.0, maximum=10.0)
    mesh_vertices: int = setting(8000, minimum=500, maximum=200000,
                                 doc="CSF-QCM mesh size; 8000 builds in ~0.4 s at 512 x 512 samples")
    max_residual_waves: float = setting(0.1, minimum=0.0, maximum=100.0,
                                        doc="a fit whose residual RMS exceeds this is flagged invalid, waves")

    @property
    def frames_per_set(self) -> int:
        return len(self.steps_deg) if self.method == "psi" else 1

    def fit_settings(self) -> FitSettings:
        return FitSettings(self.fit_method, self.modes, self.ordering, None if self.remove == "none" else self.remove,
                           self.mesh_vertices)


@dataclass(frozen=True, eq=False)
class ProcessedSet:
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
    timings_s : dict
        Seconds per stage: phase, aperture, unwrap, fit.
    fitter_kind : str or None
        For a processor without a FitterChoice (the Shack-Hartmann ``modal`` reconstructor): its name.
    residual_rms : float
        Without a FitResult: RMS of the fit residual, waves (NaN when none).
    fitter_diagnostics : dict
        Without a FitterChoice: the reconstructor's figures (e.g. its condition number).
    aperture_record : dict
        Without an Aperture: what the result records as its aperture (the lit lenslets).
    lenslets : LensletSlopes or None
        Shack-Hartmann: slopes per lenslet and the lenslets used
        (:class:`~wavestack.station.sh_processing.LensletSlopes`).
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
    fitter_kind: str | None = None
    residual_rms: float = math.nan
    fitter_diagnostics: dict[str, float | int | None] = field(default_factory=dict)
    aperture_record: dict[str, Any] = field(default_factory=dict)
    lenslets: LensletSlopes | None = None


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
        self._pending: Aperture | None = None  # a changed aperture waiting for the next set to confirm it
        self._carrier: tuple[float, float] | None = None  # sideband frequency, cycles/px (carrier method)
        self._carrier_age = 0
        self._watch: ApertureWatch | None = None
        self._aperture: Aperture | None = None
        # unwrapped on the fit's grid (every fit_decimation-th pixel): the fit sees nothing else, and
        # the spatial unwrap after an aperture change costs a quarter (0.4 s -> 0.08 s at 1024 x 1024)
        prefilter_px = settings.unwrap_prefilter_px / settings.fit_decimation  # full-resolution pixels
        self._unwrapper = TemporalUnwrapper(max_residues=settings.max_residues,
                                            params=SpatialParams(prefilter_sigma_px=prefilter_px))
        self.fitters = FitterCache(settings.fit_settings(), background=background_builds)

    def close(self) -> None:
        """Stop the background fitter builds."""
        self.fitters.close()

    def process(self, frames: Sequence[NDArray[np.generic]], *, fitter_method: str | None = None) -> ProcessedSet:
        """Process one set (psi) or one frame (carrier).

        Parameters
        ----------
        frames : sequence of ndarray, each (rows, cols)
            ``settings.frames_per_set`` frames, in stepping order.
        fitter_method : str, optional
            Fit with a fitter of this method, built synchronously (replay reproducing the fitter
            that ran live, e.g. a ``qr`` stand-in).

        Returns
        -------
        ProcessedSet
            Invalid (with a reason) rather than raising for what a live stream can throw at it:
            an empty or unsupported aperture, frames without fringes, a fit that cannot be done.

        Raises
        ------
        ValueError
            A set of the wrong length or of frames of different shapes (a wiring error).
        """
        expected = self.settings.frames_per_set
        if len(frames) != expected:
            raise ValueError(f"expected {expected} frame(s) per set, got {len(frames)}")
        timings: dict[str, float] = {}
        tick = time.perf_counter()
        try:
            wrapped, signal, erode_px = self._phase(frames)
        except ValueError as error:  # no fringes, no carrier, degenerate steps
            return self._invalid(f"phase: {error}", timings_s=timings)
        timings["phase"] = time.perf_counter() - tick

        tick = time.perf_counter()
        try:
            changed = self._update_aperture(signal, erode_px, fitter_method)
        except _ApertureUnconfirmed as change:
            return self._invalid(f"aperture: {change}", timings_s=timings)
        except (EmptyAperture, UnsupportedAperture, ValueError) as error:
            self._forget_aperture()
            return self._invalid(f"aperture: {error}", timings_s=timings)
        aperture = self._aperture
        assert aperture is not None
        timings["aperture"] = time.perf_counter() - tick

        tick = time.perf_counter()
        step = self.settings.fit_decimation
        unwrapped = self._unwrapper.update(np.ascontiguousarray(wrapped[::step, ::step]),
                                           np.ascontiguousarray(aperture.mask[::step, ::step]))
        waves = unwrapped.phase / (2.0 * np.pi)
        timings["unwrap"] = time.perf_counter() - tick

        tick = time.perf_counter()
        choice = self.fitters.current()
        assert choice is not None
        if fitter_method is not None and choice.kind != fitter_method:
            choice = self.fitters.use_method(fitter_method)
        try:
            fit = choice.fitter.fit(waves, nan_policy="omit")
        except InvalidFrame as error:
            return self._invalid(f"fit: {error}", choice=choice, aperture=aperture, aperture_changed=changed,
                                unwrap_path=unwrapped.path, timings_s=timings)
        timings["fit"] = time.perf_counter() - tick
        if not fit.residual_rms <= self.settings.max_residual_waves:  # unwrapping errors, a bad frame
            return self._invalid(f"fit: residual {fit.residual_rms:.3g} waves rms exceeds "
                                f"max_residual_waves = {self.settings.max_residual_waves:g}",
                                choice=choice, aperture=aperture, aperture_changed=changed,
                                unwrap_path=unwrapped.path, timings_s=timings)
        return ProcessedSet(True, None, fit.coefficients, fit, choice, aperture, changed, unwrapped.path, waves,
                            timings)

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

    def _update_aperture(self, signal: NDArray, erode_px: int, fitter_method: str | None) -> bool:
        """Keep, or change to, the aperture this set shows; True when a new aperture starts here.

        A change is adopted only when the next set confirms it: a phase-shifted set whose frames
        straddle the moment the optic moved shows a mixture of both apertures (measured on the
        simulated station: one component with three holes), which must not cost a fitter build.
        The straddling set itself is reported invalid (:class:`_ApertureUnconfirmed`).
        """
        if self._watch is not None and not self._watch.check(signal).changed:
            self._pending = None
            return False
        detected = detect_aperture(signal, self._detection)
        aperture = detected.aperture
        aperture = aperture.eroded(erode_px)  # the contrast box spreads the edge outward by half a box
        watch = ApertureWatch(detected.aperture.mask, detected.threshold, factor=self.settings.watch_block_px)
        if self._aperture is not None:
            difference = self._difference(self._aperture, aperture)
            if difference is None:  # the watch saw noise; the aperture holds
                self._pending, self._watch = None, watch
                return False
            if self._pending is None or self._difference(self._pending, aperture) is not None:
                self._pending = aperture  # the old watch stays, so the next set is checked in full again
                raise _ApertureUnconfirmed(f"aperture changed ({difference}); confirming on the next set")
            logger.info("aperture changed (%s): %s", difference, aperture.describe())
        self._pending, self._watch = None, watch
        step = self.settings.fit_decimation
        fit_aperture = aperture if step == 1 else Aperture.from_mask(aperture.mask[::step, ::step])
        self.fitters.new_aperture(fit_aperture, method=fitter_method)
        self._aperture = aperture
        self._carrier = None
        self._unwrapper.reset()
        return True

    def _difference(self, reference: Aperture, aperture: Aperture) -> str | None:
        """Why two apertures are not the same one (None when they are)."""
        change = compare_apertures(reference, aperture, self.settings.iou_threshold)
        return change.reason if change.changed else None

    def _invalid(self, reason: str, **fields: object) -> ProcessedSet:
        """An invalid result; the next carrier frame looks for its carrier afresh."""
        self._carrier = None
        return ProcessedSet(False, reason, **fields)  # type: ignore[arg-type]

    def _forget_aperture(self) -> None:
        self._carrier = None
        self._watch = None
        self._aperture = None
        self._pending = None
        self._unwrapper.reset()
