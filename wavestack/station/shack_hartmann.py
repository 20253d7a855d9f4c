"""One result from one Shack-Hartmann spot frame: centroids, lit lenslets, slopes, modal fit.

The Shack-Hartmann station's hot path, the counterpart of the interferometer processors
(:mod:`wavestack.pipeline.instrument`):

1. **centroid** — a thresholded centre of gravity of every subaperture of the configured
   lenslet grid (:class:`~wavestack.pipeline.Centroider`, built once per frame
   shape), restricted to the lenslets whose whole square lies inside the configured pupil
   circle (partly illuminated lenslets at the pupil edge would report the mean slope over their
   lit part only, which the modal model does not describe);
2. **lit** — of those, the lenslets whose spot is bright: thresholded intensity above
   ``min_intensity`` counts and at least ``lit_fraction`` of a typical full spot (the 90th
   percentile of the pupil's spots). A lenslet partly shadowed by an obscuration gets light in
   proportion to its lit area, so this drops the edges of a central obscuration, or a region
   that goes dark, frame by frame;
3. **slopes** — spot displacement from the *ideal* reference (the lenslet centres) divided by
   the gain ``f lambda / p**2``: wavefront slopes in waves per camera pixel, x right, y up;
4. **reconstruct** — least-squares circle-Zernike (Noll, unit RMS) coefficients over the
   configured pupil disk (:class:`~wavestack.pipeline.ModalReconstructor`),
   one matrix-vector product. The reconstructor depends on the set of lit lenslets: it is built
   when that set is new and kept in a small cache keyed by it, so a flickering edge lenslet or a
   region going dark and coming back costs one build each, not one per frame.

Nothing here uses a simulator's truth: the geometry comes from the ``[shack_hartmann]`` table
(lenslet pitch and offset, focal length, pixel size, pupil centre and radius), as on a real
sensor.

References
----------
.. [1] B. C. Platt and R. Shack, "History and principles of Shack-Hartmann wavefront sensing",
   J. Refract. Surg. 17, S573-S577 (2001).
.. [2] R. Cubalchini, "Modal wave-front estimation from phase derivative measurements",
   J. Opt. Soc. Am. 69, 972-977 (1979).
"""

from __future__ import annotations

import logging
import math
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.config import ShackHartmannSettings
from wavestack.pipeline import Centroider, LensletGrid, SpotMeasurement, convert_slopes, slopes
from wavestack.pipeline import ModalReconstructor
from wavestack.pipeline import mode_list
from wavestack.pipeline.instrument import MapStatistics
from wavestack.station.results import ApertureRecord, ReconstructorDiagnostics

logger = logging.getLogger(__name__)

#: The reconstructor's name in results (the ``fitter`` of a :class:`StationResult`).
MODAL = "modal"
_REFERENCE_PERCENTILE = 90.0  # the typical full spot: this percentile of the pupil's spot intensities


@dataclass(frozen=True, eq=False)
class LensletSlopes:
    """What the sensor measured on one frame, per lenslet (row-major, L lenslets).

    Attributes
    ----------
    grid : LensletGrid
    slopes_waves_per_px : ndarray, shape (L, 2)
        ``(dW/dx, dW/dy)``, x right, y up, waves per camera pixel; NaN where not lit.
    intensity : ndarray, shape (L,)
        Thresholded spot intensity, counts.
    pupil : ndarray of bool, shape (L,)
        Lenslets whose square lies inside the configured pupil circle.
    lit : ndarray of bool, shape (L,)
        The lenslets used: in the pupil and lit.
    """

    grid: LensletGrid
    slopes_waves_per_px: NDArray[np.float64]
    intensity: NDArray[np.float64]
    pupil: NDArray[np.bool_]
    lit: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class SlopeOutcome:
    """What one Shack-Hartmann spot frame gave.

    Attributes
    ----------
    valid : bool
        False when no trustworthy coefficients came out; ``reason`` says why.
    reason : str or None
    coefficients_waves : ndarray, shape (modes,) or None
        Noll from j = 1 (piston 0), unit RMS over the configured pupil disk, waves.
    residual_rms : float
        RMS of the slope misfit times the pitch: waves of wavefront across one lenslet (NaN when none).
    residual_pv : float
        Peak-to-valley of the same misfit (both slope components) times the pitch, waves (NaN when none).
    diagnostics : ReconstructorDiagnostics or None
    aperture_record : ApertureRecord or None
        The lit-lenslet set the result records as its aperture.
    aperture_changed : bool
        True when the lit set differs from the previous frame's.
    timings_s : dict
        Seconds per stage: centroid, slopes, reconstruct.
    lenslets : LensletSlopes or None
        Slopes per lenslet and the lenslets used.
    """

    valid: bool
    reason: str | None
    coefficients_waves: NDArray[np.float64] | None = None
    residual_rms: float = math.nan
    residual_pv: float = math.nan
    diagnostics: ReconstructorDiagnostics | None = None
    aperture_record: ApertureRecord | None = None
    aperture_changed: bool = False
    timings_s: dict[str, float] = field(default_factory=dict)
    lenslets: LensletSlopes | None = None

    fitter_kind = MODAL
    fitter_fallback = False
    normalisation = "rms"
    unwrap_path = None
    new_aperture_mask = None  # the lit set is in the result's aperture record; no mask is recorded
    quality = None  # no per-lenslet quality counts yet

    @property
    def statistics(self) -> MapStatistics:
        """The residual's RMS and PV; the wavefront's PV and PVr are not computed from slopes yet (NaN)."""
        return MapStatistics(self.residual_rms, self.residual_pv, math.nan, math.nan)


def pupil_lenslets(grid: LensletGrid, centre_px: tuple[float, float], radius_px: float) -> NDArray[np.bool_]:
    """Lenslets whose whole square subaperture lies inside a circle.

    A square is inside when its corner farthest from the centre is, at distance
    ``hypot(|dc| + p/2, |dr| + p/2)`` for a lenslet centre offset ``(dc, dr)`` and pitch ``p``.

    Parameters
    ----------
    grid : LensletGrid
    centre_px : (float, float)
        ``(col, row)`` of the circle's centre, pixels.
    radius_px : float
        Pixels.

    Returns
    -------
    ndarray of bool, shape (L,)
        Row-major.
    """
    centres = grid.centres().reshape(-1, 2)
    half = 0.5 * grid.pitch_px
    far = np.hypot(np.abs(centres[:, 0] - centre_px[0]) + half, np.abs(centres[:, 1] - centre_px[1]) + half)
    return far <= radius_px


def coefficient_errors(measured: ArrayLike, true: ArrayLike, *, first_term: int = 4) -> tuple[float, float]:
    """RMS wavefront of the true coefficients, and of measured minus true, from Noll ``first_term`` on.

    For the unit-RMS circle Zernike basis over the pupil disk the wavefront RMS over the disk is
    the root of the sum of squared coefficients (the basis is orthonormal), so both figures are
    wavefront RMS over the disk, waves. Piston is not sensed by slopes and tilt is alignment,
    hence ``first_term = 4`` by default. Only the terms both vectors describe are compared (the
    measured subspace; a true vector shorter than the measured one counts as zero beyond its end).

    Parameters
    ----------
    measured : array_like, shape (M,)
        Reconstructed coefficients, Noll from j = 1, waves.
    true : array_like, shape (J,)
        True coefficients in the same basis over the same pupil, waves.
    first_term : int
        First Noll index compared.

    Returns
    -------
    truth_rms, error_rms : float
        Waves.
    """
    found = np.asarray(measured, dtype=np.float64)
    reference = np.zeros(found.size)
    given = np.asarray(true, dtype=np.float64)[: found.size]
    reference[: given.size] = given
    start = first_term - 1
    return (float(np.sqrt(np.sum(reference[start:] ** 2))),
            float(np.sqrt(np.sum((found[start:] - reference[start:]) ** 2))))


@dataclass(frozen=True, eq=False)
class _Geometry:
    """Everything that depends only on the configuration and the frame shape."""

    frame_shape: tuple[int, int]
    grid: LensletGrid
    centroider: Centroider
    centres_px: NDArray[np.float64]  # (L, 2) the ideal reference
    centres_xy: NDArray[np.float64]  # (L, 2) x right, y up
    pupil: NDArray[np.bool_]  # (L,)


class SlopeProcessor:
    """Turns Shack-Hartmann spot frames into Zernike coefficients (waves), keeping state between frames.

    Same interface as the interferometer processors: ``process`` takes a
    set of one frame and returns a :class:`SlopeOutcome`, invalid
    with a reason rather than raising for what a live stream can bring (no spots, too few lit
    lenslets, a reconstruction that cannot be done).

    Parameters
    ----------
    settings : ShackHartmannSettings
    wavelength_nm : float
        The wavelength the coefficients are counted in, nm.
    """

    frames_per_set = 1

    def __init__(self, settings: ShackHartmannSettings, *, wavelength_nm: float) -> None:
        if not wavelength_nm > 0:
            raise ValueError(f"wavelength_nm must be > 0, got {wavelength_nm!r}")
        self.settings = settings
        self.wavelength_nm = float(wavelength_nm)
        self._modes = tuple(mode_list("noll", settings.modes))
        self._geometry: _Geometry | None = None
        self._reconstructors: OrderedDict[bytes, ModalReconstructor] = OrderedDict()
        self._lit_key: bytes | None = None
        self._lit_sets = -1  # counts lit-lenslet sets as the aperture ids of an interferometer
        self.builds = 0  # reconstructors built so far (cache misses)

    def process(self, frames: Sequence[NDArray[np.generic]], *, fitter_method: str | None = None) -> SlopeOutcome:
        """Process one spot frame.

        Parameters
        ----------
        frames : sequence of one ndarray, shape (rows, cols)
        fitter_method : str, optional
            Only ``"modal"`` (or None) exists; accepted so replay can pass the recorded one.

        Returns
        -------
        SlopeOutcome
            ``coefficients_waves`` Noll from j = 1 (piston 0), unit RMS over the configured pupil
            disk; ``lenslets`` the slopes and lit lenslets; ``aperture_record`` the lit set.

        Raises
        ------
        ValueError
            Not exactly one 2-D frame, or an unknown ``fitter_method`` (wiring errors).
        """
        if len(frames) != 1:
            raise ValueError(f"expected 1 frame per set, got {len(frames)}")
        if fitter_method not in (None, MODAL):
            raise ValueError(f"fitter_method: expected {MODAL!r} or None, got {fitter_method!r}")
        frame = np.asarray(frames[0])
        if frame.ndim != 2:
            raise ValueError(f"expected a 2-D frame, got shape {frame.shape}")
        timings: dict[str, float] = {}
        tick = time.perf_counter()
        try:
            geometry = self._geometry_for((int(frame.shape[0]), int(frame.shape[1])))
        except ValueError as error:
            return SlopeOutcome(False, f"geometry: {error}", timings_s=timings)
        spots = geometry.centroider.measure(frame)
        timings["centroid"] = time.perf_counter() - tick

        tick = time.perf_counter()
        lit, problem = self._lit(spots, geometry.pupil)
        measured = SpotMeasurement(spots.centroids, spots.intensity, lit)
        result = slopes(measured, geometry.centres_px, self.settings.focal_length_um, self.settings.pixel_um)
        slope_x, slope_y = convert_slopes(result, wavefront_unit_um=self.wavelength_nm * 1e-3,
                                          length_unit_um=self.settings.pixel_um)
        lenslets = LensletSlopes(geometry.grid, np.column_stack([slope_x, slope_y]), spots.intensity,
                                 geometry.pupil, lit)
        timings["slopes"] = time.perf_counter() - tick
        if problem is not None:
            return SlopeOutcome(False, f"lenslets: {problem}", timings_s=timings, lenslets=lenslets)

        tick = time.perf_counter()
        changed = self._note_lit_set(lit)
        record = self._record(geometry, lit, changed)
        try:
            reconstructor = self._reconstructor(geometry, lit)
        except ValueError as error:
            return SlopeOutcome(False, f"reconstruct: {error}", aperture_changed=changed, aperture_record=record,
                                timings_s=timings, lenslets=lenslets)
        diagnostics = ReconstructorDiagnostics(condition=reconstructor.condition, lit_lenslets=int(lit.sum()),
                                               pupil_lenslets=int(geometry.pupil.sum()))
        if not reconstructor.condition <= self.settings.max_condition:
            return SlopeOutcome(False, f"reconstruct: condition number {reconstructor.condition:.3g} of the lit "
                                f"lenslets exceeds max_condition {self.settings.max_condition:g}",
                                diagnostics=diagnostics, aperture_changed=changed, aperture_record=record,
                                timings_s=timings, lenslets=lenslets)
        coefficients = reconstructor.reconstruct(slope_x, slope_y)
        model_x, model_y = reconstructor.predict(coefficients)
        misfit = np.concatenate([slope_x[lit] - model_x[lit], slope_y[lit] - model_y[lit]])
        # slope residual (waves per pixel) times the pitch: waves of wavefront across one lenslet
        residual = float(np.sqrt(np.mean(misfit ** 2))) * self.settings.pitch_px
        residual_pv = float(misfit.max() - misfit.min()) * self.settings.pitch_px
        timings["reconstruct"] = time.perf_counter() - tick
        return SlopeOutcome(True, None, coefficients, residual_rms=residual, residual_pv=residual_pv,
                            diagnostics=diagnostics,
                            aperture_changed=changed, aperture_record=record, timings_s=timings, lenslets=lenslets)

    # ------------------------------------------------------------------ stages

    def _geometry_for(self, frame_shape: tuple[int, int]) -> _Geometry:
        if self._geometry is not None and self._geometry.frame_shape == frame_shape:
            return self._geometry
        s = self.settings
        grid = s.grid_for(frame_shape)
        pupil = pupil_lenslets(grid, s.pupil_centre_px, s.pupil_radius_px)
        if not pupil.any():
            raise ValueError(f"no lenslet of {grid} lies inside the pupil circle centred at {s.pupil_centre_px} "
                             f"of radius {s.pupil_radius_px} px")
        centroider = Centroider.build(grid, frame_shape, threshold=s.centroid_threshold,
                                      min_intensity=s.min_intensity, mask=pupil.reshape(grid.shape))
        self._geometry = _Geometry(frame_shape, grid, centroider, grid.centres().reshape(-1, 2),
                                   grid.centres_xy(), pupil)
        self._reconstructors.clear()
        self._lit_key = None
        logger.info("Shack-Hartmann geometry: %s, %d lenslets in the pupil", grid, int(pupil.sum()))
        return self._geometry

    def _lit(self, spots: SpotMeasurement, pupil: NDArray[np.bool_]) -> tuple[NDArray[np.bool_], str | None]:
        """The lit lenslets and, when there are too few, why."""
        s = self.settings
        bright = spots.valid  # in the pupil, above min_intensity, finite
        wanted = max(1, math.ceil(s.min_lit_fraction * int(pupil.sum())))
        if not bright.any():
            return bright, f"no spot above min_intensity {s.min_intensity:g} counts in the pupil"
        reference = float(np.percentile(spots.intensity[bright], _REFERENCE_PERCENTILE))
        lit = bright & (spots.intensity >= s.lit_fraction * reference)
        count = int(lit.sum())
        if count < wanted:
            return lit, (f"{count} of {int(pupil.sum())} pupil lenslets lit; expected at least {wanted} "
                         f"(min_lit_fraction {s.min_lit_fraction:g})")
        return lit, None

    def _note_lit_set(self, lit: NDArray[np.bool_]) -> bool:
        """Count a new lit-lenslet set; True when it differs from the previous result's."""
        key = np.packbits(lit).tobytes()
        if key == self._lit_key:
            return False
        self._lit_key = key
        self._lit_sets += 1
        return True

    def _record(self, geometry: _Geometry, lit: NDArray[np.bool_], changed: bool) -> ApertureRecord:
        count = int(lit.sum())
        window = int(math.floor(geometry.grid.pitch_px))
        return ApertureRecord(id=self._lit_sets, changed=changed,
                              topology=f"{count} of {int(geometry.pupil.sum())} pupil lenslets lit "
                                       f"({geometry.grid.shape[0]} x {geometry.grid.shape[1]} grid)",
                              valid_lenslets=count, valid_pixels=count * window * window)

    def _reconstructor(self, geometry: _Geometry, lit: NDArray[np.bool_]) -> ModalReconstructor:
        """The reconstructor for this lit set: from the cache, or built (and cached) now."""
        key = np.packbits(lit).tobytes()
        found = self._reconstructors.get(key)
        if found is not None:
            self._reconstructors.move_to_end(key)
            return found
        s = self.settings
        centre = (s.pupil_centre_px[0], -s.pupil_centre_px[1])  # (col, row) -> (x, y), y up
        built = ModalReconstructor.for_circle(geometry.centres_xy, centre, s.pupil_radius_px, self._modes, lit)
        self.builds += 1
        self._reconstructors[key] = built
        while len(self._reconstructors) > s.reconstructor_cache:
            self._reconstructors.popitem(last=False)
        logger.debug("modal reconstructor for %d lit lenslets (condition %.3g)", int(lit.sum()), built.condition)
        return built
