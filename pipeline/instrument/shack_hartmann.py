"""The Shack-Hartmann processor: one spot frame in, one frozen outcome out, for every command.

:class:`ShackHartmannProcessor` is the one signal path of a Shack-Hartmann sensor: the live
station, ``replay``, ``batch`` and ``analyze`` (a spot image, with or without the station's
configuration) all call :meth:`~ShackHartmannProcessor.process`. It knows nothing of devices or
threads; its state is explicit (:attr:`~ShackHartmannProcessor.state`: the lenslet geometry,
built from the reference frame, and the lit-lenslet set of the last frame) and its reconstructors
sit in a :class:`ReconstructorCache` that the caller may pass in. Per frame:

1. **centroid**: a thresholded centre of gravity of every pupil lenslet's window
   (:class:`~wavestack.pipeline.shack_hartmann.Centroider`, built once per geometry);
2. **lit**: the lenslets whose spot is bright, by the one rule
   (:func:`~wavestack.pipeline.shack_hartmann.lit_lenslets`: ``lit_fraction`` of a typical full
   spot), so the edges of an obscuration, or a region that goes dark, drop out frame by frame;
3. **slopes**: spot displacement from the reference divided by the gain ``f lambda / p**2``:
   wavefront slopes in waves per camera pixel, x right, y up;
4. **reconstruct**: least-squares circle-Zernike coefficients (unit RMS) over the pupil disk
   (:class:`~wavestack.pipeline.shack_hartmann.ModalReconstructor`), one matrix-vector product;
   the reconstructor depends on the lit set and is cached by it, so a flickering edge lenslet
   costs one build, not one per frame.

What a live stream can bring (no spots, too few lit lenslets, a reference frame without a
lattice, a reconstruction that cannot be done) gives an invalid outcome with the reason; only
wiring errors raise. A frame shows no spots when its typical window holds less than a tenth of
the reference frame's typical spot (or none passes ``min_intensity``).

References
----------
.. [1] B. C. Platt and R. Shack, "History and principles of Shack-Hartmann wavefront sensing",
   J. Refract. Surg. 17, S573-S577 (2001).
.. [2] R. Cubalchini, "Modal wave-front estimation from phase derivative measurements",
   J. Opt. Soc. Am. 69, 972-977 (1979).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..shack_hartmann import LensletLattice, ModalReconstructor, SpotMeasurement, convert_slopes, lit_lenslets, slopes
from ..shack_hartmann.lit import TYPICAL_SPOT_PERCENTILE
from ..zernike import mode_list, zernike_basis
from .lenslet_geometry import LensletGeometry, lenslet_geometry
from .records import ApertureRecord, ReconstructorDiagnostics
from .sensor_setup import ShackHartmannSetup
from .statistics import MapStatistics

logger = logging.getLogger(__name__)

#: The reconstructor's name in results (the ``fitter`` of a station result).
MODAL = "modal"
# A frame whose typical window holds less than this fraction of the reference frame's typical spot
# shows no spots (light off, a shutter closed): a spot sums the beam's power over its lenslet, a
# window of background and read noise a few per mille of it.
_NO_SPOTS = 0.1


@dataclass(frozen=True, eq=False)
class LensletSlopes:
    """What the sensor measured on one frame, per lenslet (L lenslets, in the lattice's order).

    Attributes
    ----------
    lattice : LensletLattice
    slopes_waves_per_px : ndarray, shape (L, 2)
        ``(dW/dx, dW/dy)``, x right, y up, waves per camera pixel; NaN where not lit.
    intensity : ndarray, shape (L,)
        Thresholded spot intensity, counts.
    pupil : ndarray of bool, shape (L,)
        The pupil lenslets (whole cell inside the pupil disk, with a reference spot).
    lit : ndarray of bool, shape (L,)
        The lenslets used: in the pupil and lit.
    """

    lattice: LensletLattice
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
        The setup's ordering, unit RMS over the pupil disk, waves; piston 0 (not sensed).
    residual_rms : float
        RMS of the slope misfit times the pitch: waves of wavefront across one lenslet (NaN when none).
    residual_pv : float
        Peak-to-valley of the same misfit (both slope components) times the pitch, waves (NaN when none).
    pv : float
        Peak-to-valley of the reconstructed wavefront less piston and tilt, at the lit lenslets'
        centres (the points the sensor samples), waves (NaN when none).
    diagnostics : ReconstructorDiagnostics or None
    aperture_record : ApertureRecord or None
        The lit-lenslet set the result records as its aperture.
    aperture_changed : bool
        True when the lit set differs from the previous frame's.
    timings_s : dict
        Seconds per stage: centroid, slopes, reconstruct.
    lenslets : LensletSlopes or None
        Slopes per lenslet and the lenslets used.
    tilt_measured : bool
        False when the lattice sits on the frame's own spots (no reference): tilt reads 0 then.
    pupil_px : (float, float, float) or None
        ``(col, row, radius)`` of the disk the coefficients live on, pixels.
    """

    valid: bool
    reason: str | None
    coefficients_waves: NDArray[np.float64] | None = None
    residual_rms: float = math.nan
    residual_pv: float = math.nan
    pv: float = math.nan
    diagnostics: ReconstructorDiagnostics | None = None
    aperture_record: ApertureRecord | None = None
    aperture_changed: bool = False
    timings_s: dict[str, float] = field(default_factory=dict)
    lenslets: LensletSlopes | None = None
    tilt_measured: bool = True
    pupil_px: tuple[float, float, float] | None = None

    fitter_kind = MODAL
    fitter_fallback = False
    normalisation = "rms"
    unwrap_path = None
    new_aperture_mask = None  # the lit set is in the result's aperture record; no mask is recorded
    quality = None  # no per-lenslet quality counts yet
    calibration = None  # a reference calibration applies to interferometer maps

    @property
    def statistics(self) -> MapStatistics:
        """The residual's RMS and PV and the wavefront's PV; no PVr (NaN): Evans' robust PV adds three
        times a measured map's residual RMS to its fit's PV, and slopes give no map."""
        return MapStatistics(self.residual_rms, self.residual_pv, self.pv, math.nan)


@dataclass(frozen=True, eq=False)
class ShackHartmannState:
    """The processor's state between frames.

    Attributes
    ----------
    geometry : LensletGeometry or None
        The lattice, reference and pupil lenslets; None until a reference frame gave them.
    lit_key : bytes or None
        The last frame's lit set (packed bits).
    lit_sets : int
        Lit sets seen so far minus one: the id of the current one (-1 before the first).
    """

    geometry: LensletGeometry | None = None
    lit_key: bytes | None = None
    lit_sets: int = -1


class ReconstructorCache:
    """Modal reconstructors by lit-lenslet set, least recently used dropped beyond ``capacity``.

    Parameters
    ----------
    capacity : int
        Sets kept, ``>= 1``.
    """

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity: expected >= 1 lit sets, got {capacity!r}")
        self.capacity = int(capacity)
        self.builds = 0  # reconstructors built so far (misses)
        self._kept: OrderedDict[bytes, ModalReconstructor] = OrderedDict()

    def clear(self) -> None:
        """Forget every reconstructor (the geometry changed)."""
        self._kept.clear()

    def get(self, key: bytes, build: Callable[[], ModalReconstructor]) -> ModalReconstructor:
        """The reconstructor kept for ``key``, or ``build()`` kept now.

        Raises
        ------
        ValueError
            What ``build`` raises (nothing is kept then).
        """
        found = self._kept.get(key)
        if found is not None:
            self._kept.move_to_end(key)
            return found
        built = build()
        self.builds += 1
        self._kept[key] = built
        while len(self._kept) > self.capacity:
            self._kept.popitem(last=False)
        return built



class ShackHartmannProcessor:
    """Turns Shack-Hartmann spot frames into Zernike coefficients (waves), keeping state between frames.

    Parameters
    ----------
    setup : ShackHartmannSetup
    reference_frame : array_like, optional
        A flat wavefront's spot frame: the lattice (and, with ``reference = "frame"``, the
        reference spots) come from it. Default: the first frame processed (of each new shape).
    reconstructors : ReconstructorCache, optional
        Default: a new one of ``setup.reconstructor_cache`` sets.

    Raises
    ------
    ValueError
        ``reference = "frame"`` without a reference frame.

    Examples
    --------
    A 7 x 8 square array of 16 px lenslets, spots where a flat wavefront puts them, then the
    same spots moved one pixel right: a tilt about x of 1 / gain waves per pixel.

    >>> import numpy as np
    >>> rows, cols = np.mgrid[:128, :144]
    >>> def spots(shift):
    ...     frame = np.full((128, 144), 10.0)
    ...     for row in 8 + 16 * np.arange(7):
    ...         for col in 8 + 16 * np.arange(8) + shift:
    ...             frame += 1000 * np.exp(-((cols - col) ** 2 + (rows - row) ** 2) / 4.5)
    ...     return frame
    >>> setup = ShackHartmannSetup(focal_length_um=2000, pixel_um=5, wavelength_nm=500, lattice="square",
    ...                            pitch_px=16, offset_px=(0.0, 0.0), pupil_px=(64.0, 56.0, 86.0), modes=6)
    >>> processor = ShackHartmannProcessor(setup)
    >>> flat, tilted = processor.process([spots(0.0)]), processor.process([spots(1.0)])
    >>> flat.valid, int(flat.diagnostics.lit_lenslets), bool(np.abs(flat.coefficients_waves).max() < 1e-3)
    (True, 56, True)
    >>> round(float(tilted.coefficients_waves[1]) * 2 / 86.0 * setup.gain_px, 3)  # tilt x slope * gain: 1 px
    1.0
    """

    frames_per_set = 1

    def __init__(self, setup: ShackHartmannSetup, *, reference_frame: ArrayLike | None = None,
                 reconstructors: ReconstructorCache | None = None) -> None:
        if setup.reference == "frame" and reference_frame is None:
            raise ValueError("reference_frame: reference = 'frame' needs the flat wavefront's spot frame")
        self.setup = setup
        self._reference = None if reference_frame is None else np.asarray(reference_frame)
        self._modes = tuple(mode_list(setup.ordering, setup.modes))
        self.reconstructors = reconstructors or ReconstructorCache(setup.reconstructor_cache)
        self.state = ShackHartmannState()

    @property
    def builds(self) -> int:
        """Reconstructors built so far."""
        return self.reconstructors.builds

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
            geometry = self._geometry_for(frame)
        except ValueError as error:
            return SlopeOutcome(False, f"lattice: {error}", timings_s=timings)
        spots = geometry.centroider.measure(frame)
        timings["centroid"] = time.perf_counter() - tick

        tick = time.perf_counter()
        lit, problem = self._lit(spots, geometry)
        measured = SpotMeasurement(spots.centroids, spots.intensity, lit)
        result = slopes(measured, geometry.reference_px, self.setup.focal_length_um, self.setup.pixel_um)
        slope_x, slope_y = convert_slopes(result, wavefront_unit_um=self.setup.wavelength_nm * 1e-3,
                                          length_unit_um=self.setup.pixel_um)
        lenslets = LensletSlopes(geometry.lattice, np.column_stack([slope_x, slope_y]), spots.intensity,
                                 geometry.in_pupil, lit)
        timings["slopes"] = time.perf_counter() - tick
        common = {"timings_s": timings, "lenslets": lenslets, "tilt_measured": geometry.tilt_measured,
                  "pupil_px": geometry.pupil_px}
        if problem is not None:
            return SlopeOutcome(False, f"lenslets: {problem}", **common)

        tick = time.perf_counter()
        changed = self._note_lit_set(lit)
        record = self._record(geometry, lit, changed)
        try:
            reconstructor = self.reconstructors.get(np.packbits(lit).tobytes(), lambda: self._build(geometry, lit))
        except ValueError as error:
            return SlopeOutcome(False, f"reconstruct: {error}", aperture_changed=changed, aperture_record=record,
                                **common)
        diagnostics = ReconstructorDiagnostics(condition=reconstructor.condition, lit_lenslets=int(lit.sum()),
                                               pupil_lenslets=int(geometry.in_pupil.sum()))
        if not reconstructor.condition <= self.setup.max_condition:
            return SlopeOutcome(False, f"reconstruct: condition number {reconstructor.condition:.3g} of the lit "
                                f"lenslets exceeds max_condition {self.setup.max_condition:g}",
                                diagnostics=diagnostics, aperture_changed=changed, aperture_record=record, **common)
        coefficients = reconstructor.reconstruct(slope_x, slope_y)
        model_x, model_y = reconstructor.predict(coefficients)
        misfit = np.concatenate([slope_x[lit] - model_x[lit], slope_y[lit] - model_y[lit]])
        if not geometry.tilt_measured:  # the lattice sits on the spots: their mean displacement is not seen
            coefficients[[index for index, (n, _) in enumerate(self._modes) if n == 1]] = 0.0
        # slope residual (waves per pixel) times the pitch: waves of wavefront across one lenslet
        pitch = geometry.lattice.pitch_px
        timings["reconstruct"] = time.perf_counter() - tick
        return SlopeOutcome(True, None, coefficients, residual_rms=float(np.sqrt(np.mean(misfit ** 2))) * pitch,
                            residual_pv=float(misfit.max() - misfit.min()) * pitch,
                            pv=_wavefront_pv(geometry, lit, self._modes, coefficients), diagnostics=diagnostics,
                            aperture_changed=changed, aperture_record=record, **common)

    # ------------------------------------------------------------------ stages

    def _geometry_for(self, frame: NDArray) -> LensletGeometry:
        """The geometry for this frame's shape, built from the reference frame (or this frame) when new."""
        shape = (int(frame.shape[0]), int(frame.shape[1]))
        current = self.state.geometry
        if current is not None and current.frame_shape == shape:
            return current
        reference = frame if self._reference is None else self._reference
        geometry = lenslet_geometry(self.setup, shape, reference)
        self.reconstructors.clear()
        self.state = ShackHartmannState(geometry, None, self.state.lit_sets)
        return geometry

    def _lit(self, spots: SpotMeasurement, geometry: LensletGeometry) -> tuple[NDArray[np.bool_], str | None]:
        """The lit lenslets and, when there are too few, why."""
        setup = self.setup
        pupil = geometry.in_pupil
        wanted = max(1, math.ceil(setup.min_lit_fraction * int(pupil.sum())))
        if not spots.valid.any():  # valid: in the pupil, above min_intensity, finite
            return spots.valid, f"no spot above min_intensity {setup.min_intensity:g} counts in the pupil"
        typical = float(np.percentile(spots.intensity[spots.valid], TYPICAL_SPOT_PERCENTILE))
        if typical < _NO_SPOTS * geometry.typical_spot:
            return np.zeros_like(spots.valid), (
                f"no spots: the typical window holds {typical:.3g} counts, {typical / geometry.typical_spot:.1%} of the "
                f"reference frame's typical spot; expected at least {_NO_SPOTS:.0%}")
        lit = lit_lenslets(spots.intensity, spots.valid, setup.lit_fraction)
        count = int(lit.sum())
        if count < wanted:
            return lit, (f"{count} of {int(pupil.sum())} pupil lenslets lit; expected at least {wanted} "
                         f"(min_lit_fraction {setup.min_lit_fraction:g})")
        return lit, None

    def _note_lit_set(self, lit: NDArray[np.bool_]) -> bool:
        """Count a new lit-lenslet set; True when it differs from the previous frame's."""
        key = np.packbits(lit).tobytes()
        if key == self.state.lit_key:
            return False
        self.state = dataclasses.replace(self.state, lit_key=key, lit_sets=self.state.lit_sets + 1)
        return True

    def _record(self, geometry: LensletGeometry, lit: NDArray[np.bool_], changed: bool) -> ApertureRecord:
        count = int(lit.sum())
        window = geometry.lattice.window_width()
        return ApertureRecord(id=self.state.lit_sets, changed=changed,
                              topology=f"{count} of {int(geometry.in_pupil.sum())} pupil lenslets lit "
                                       f"({geometry.lattice.kind} lattice, pitch {geometry.lattice.pitch_px:.2f} px)",
                              valid_lenslets=count, valid_pixels=count * window * window)

    def _build(self, geometry: LensletGeometry, lit: NDArray[np.bool_]) -> ModalReconstructor:
        cx, cy, radius = geometry.pupil_px
        built = ModalReconstructor.for_circle(geometry.lattice.centres_xy(), (cx, -cy), radius, self._modes, lit)
        logger.debug("modal reconstructor for %d lit lenslets (condition %.3g)", int(lit.sum()), built.condition)
        return built


def _wavefront_pv(geometry: LensletGeometry, lit: NDArray[np.bool_], modes: Sequence[tuple[int, int]],
                  coefficients: NDArray[np.float64]) -> float:
    """PV of the modal wavefront less piston and tilt (radial order <= 1) at the lit lenslets' centres, waves."""
    cx, cy, radius = geometry.pupil_px
    centres = geometry.lattice.centres()[lit]  # (col, row), pixels
    higher = [k for k, (n, _) in enumerate(modes) if n >= 2]
    if not higher or centres.shape[0] == 0:
        return math.nan
    values = zernike_basis([modes[k] for k in higher], (centres[:, 0] - cx) / radius,
                           (cy - centres[:, 1]) / radius) @ coefficients[higher]
    return float(values.max() - values.min())
