"""Finding the lenslet grid from a reference frame: the pitch from the periodogram of the row and
column profiles, the phase of the grid from the folded profiles, then a refinement on the spot
centroids of the lit lenslets.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize_scalar

from .._checks import finite_float
from .centroids import _gather_rows_cols, camera_frame, Centroider
from .grid import _EDGE_TOL, _MIN_PITCH_PX, LensletGrid

logger = logging.getLogger(__name__)


_PAD = 8  # zero-padding factor of the periodogram in detect_grid
_MIN_PERIODS = 4  # detect_grid needs at least this many periods across each axis
_LIT_FRACTION = 0.25  # detect_grid: a lenslet is lit above bg + this * (typical peak - bg)
_PITCH_MISMATCH = 0.005  # relative row/column pitch difference that detect_grid reports


# relative row/column pitch difference that detect_grid refuses: the periodogram pitches of a
# small array differ by a few per cent; a hexagonal array's by 42 % (p / 2 against p sqrt(3) / 2)
_PITCH_REFUSED = 0.05


_RESIDUAL = 0.25  # detect_grid refuses a grid with a lit spot farther than this many pitches from its centre


def detect_grid(frame: ArrayLike, pitch_px_guess: float | None = None) -> LensletGrid:
    """Find the lenslet grid from a frame of spots (ideally a flat-wavefront reference frame).

    Steps:

    1. Project the frame on its columns and rows (sums along the other axis): each
       projection is a comb of period ``pitch`` under the pupil envelope.
    2. Pitch per axis: the largest peak of the zero-padded periodogram of the mean-removed
       projection (within ``[0.8, 1.25] * pitch_px_guess`` if given, else between 4 pixels and
       a quarter of the frame), refined by maximising ``|sum_x P(x) exp(-2 pi i x / p)|``
       over continuous ``p`` (Brent). The grid is square, so the two are averaged.
    3. Offset by folding: the circular mean of the projection folded modulo the pitch,
       ``arg sum_x P(x) exp(2 pi i x / p)``, places the spot comb; the lenslet centres are
       taken at the spots.
    4. Extent: every lenslet whose window fits in the frame is tested for a spot (window
       peak above ``median(frame) + 0.25 * (90th percentile of window peaks - median)``); the
       grid is the bounding box of the lit lenslets.
    5. Refinement: the lit spots are centroided on that grid and ``col = c0 + p j``,
       ``row = r0 + p i`` (one pitch ``p``) fitted to them by least squares. The periodogram
       pitch is biased by the pupil envelope by a few 1e-3 pixel, a tenth of a pixel across
       40 lenslets; the fit is limited only by the centroid noise. Every lit spot must lie
       within a quarter pitch of its fitted centre.

    Parameters
    ----------
    frame : array_like, shape (rows, cols)
        Camera frame, any real dtype and memory layout, background roughly uniform.
    pitch_px_guess : float, optional
        Approximate pitch in pixels; narrows the search to ``[0.8, 1.25]`` times it.

    Returns
    -------
    LensletGrid
        Pitch, corner offset and shape of the lit part of the array.

    Raises
    ------
    ValueError
        If ``frame`` is not a finite real 2-D array, ``pitch_px_guess`` is not a number
        ``>= 4``, no periodic spot pattern is found, the pitches along the rows and columns
        differ by more than 5 % (a hexagonal or rectangular array), or a lit spot lies more
        than a quarter pitch from its fitted lenslet centre: never a grid that does not match
        the spots. :func:`~wavestack.pipeline.shack_hartmann.detect_lattice` fits hexagonal
        and turned lattices.

    Notes
    -----
    Limits: the spots must repeat on a square, axis-aligned grid (rotation of the lenslet
    array against the pixel grid is not estimated; a rotation of ``a`` radians smears the
    projections by ``a * extent`` pixels); at least 4 periods across each axis and a spot
    smaller than about a quarter of the pitch, so that the fundamental dominates the
    periodogram; and at least ~10 % of the candidate windows lit. The grid is placed on the
    *spots*: on an aberrated frame the offset includes the mean tilt and the pitch the
    defocus (a defocus with displacement ``k * x`` scales the pitch by ``1 + k``), so detect
    on a reference frame. Lenslets that are dim (partly illuminated at the pupil edge) may
    fall outside the bounding box.
    """
    image = camera_frame(frame).astype(np.float64, copy=False)
    if not np.all(np.isfinite(image)):
        raise ValueError("frame must be finite, got NaN or infinite pixels")
    guess = None if pitch_px_guess is None else finite_float(pitch_px_guess, "pitch_px_guess")
    if guess is not None and guess < _MIN_PITCH_PX:
        raise ValueError(f"pitch_px_guess must be >= {_MIN_PITCH_PX} pixels, got {guess!r}")
    col_profile = image.sum(axis=0)  # a function of the column
    row_profile = image.sum(axis=1)  # a function of the row
    pitch_col = _profile_period(col_profile, guess, "columns")
    pitch_row = _profile_period(row_profile, guess, "rows")
    mismatch = abs(pitch_col - pitch_row) / max(pitch_col, pitch_row)
    if _PITCH_MISMATCH < mismatch <= _PITCH_REFUSED:
        logger.warning(
            "pitch along columns %.4f px and rows %.4f px differ; using their mean", pitch_col, pitch_row
        )
    if mismatch > _PITCH_REFUSED:
        raise ValueError(
            f"frame: the spots repeat every {pitch_col:.2f} px along the columns and {pitch_row:.2f} px along "
            f"the rows; expected one square grid (detect_lattice finds hexagonal and turned lattices)"
        )
    pitch = 0.5 * (pitch_col + pitch_row)
    spot_col = _fold(col_profile, pitch)
    spot_row = _fold(row_profile, pitch)
    return _lit_grid(image, pitch, spot_col, spot_row)


def _profile_period(profile: NDArray[np.float64], guess: float | None, axis: str) -> float:
    """Period of the spot comb in a projection (periodogram peak, then Brent refinement)."""
    n = profile.size
    signal = profile - profile.mean()
    longest = n / _MIN_PERIODS
    if longest < _MIN_PITCH_PX:
        raise ValueError(f"frame has only {n} {axis}; too few to hold {_MIN_PERIODS} lenslets")
    low_p, high_p = (_MIN_PITCH_PX, longest) if guess is None else (0.8 * guess, 1.25 * guess)
    size = _PAD * n
    power = np.abs(np.fft.rfft(signal, size)) ** 2
    freqs = np.arange(power.size) / size
    band = (freqs >= 1.0 / high_p) & (freqs <= 1.0 / low_p)
    if not band.any() or not np.any(power[band] > 0):
        raise ValueError(f"frame: no periodic spot pattern along the {axis}; expected a lenslet grid")
    peak = np.flatnonzero(band)[np.argmax(power[band])]
    positions = np.arange(n)

    def negative_amplitude(nu: float) -> float:
        """Minus the magnitude of the projection's Fourier sum at frequency ``nu``."""
        return -abs(np.dot(signal, np.exp(-2j * np.pi * nu * positions)))

    step = 1.0 / size
    best = minimize_scalar(
        negative_amplitude,
        bounds=(freqs[peak] - 1.5 * step, freqs[peak] + 1.5 * step),
        method="bounded",
        options={"xatol": 1e-12},
    )
    return float(1.0 / best.x)


def _fold(profile: NDArray[np.float64], pitch: float) -> float:
    """Position in ``[0, pitch)`` of the spot comb: circular mean of the folded profile."""
    positions = np.arange(profile.size)
    weights = profile - profile.mean()
    phasor = np.dot(weights, np.exp(2j * np.pi * positions / pitch))
    return float(np.mod(np.angle(phasor) * pitch / (2.0 * np.pi), pitch))


def _lit_grid(image: NDArray[np.float64], pitch: float, spot_col: float, spot_row: float) -> LensletGrid:
    """Bounding box of the lenslets (spots at ``spot + n * pitch``) whose windows hold a spot,
    with pitch and offset refined by a straight-line fit to the lit spots' centroids."""
    width = int(math.floor(pitch + _EDGE_TOL))
    first_row, n_rows = _fitting_range(spot_row, pitch, width, image.shape[0])
    first_col, n_cols = _fitting_range(spot_col, pitch, width, image.shape[1])
    if n_rows < 1 or n_cols < 1:
        raise ValueError(
            f"frame of shape {image.shape} holds no complete lenslet window of pitch {pitch:.3f}"
        )
    corner = (spot_col + (first_col - 0.5) * pitch, spot_row + (first_row - 0.5) * pitch)
    candidate = LensletGrid(pitch_px=pitch, offset_px=corner, shape=(n_rows, n_cols))
    peaks = _gather_windows(image, *candidate.window_starts()).max(axis=(1, 3))
    background = float(np.median(image))
    typical = float(np.percentile(peaks, 90))
    if not typical > background:
        raise ValueError("frame: no spots above the background; expected a Shack-Hartmann frame")
    lit = peaks > background + _LIT_FRACTION * (typical - background)
    lit_rows = np.flatnonzero(lit.any(axis=1))
    lit_cols = np.flatnonzero(lit.any(axis=0))
    offset = (corner[0] + lit_cols[0] * pitch, corner[1] + lit_rows[0] * pitch)
    shape = (int(lit_rows[-1] - lit_rows[0] + 1), int(lit_cols[-1] - lit_cols[0] + 1))
    coarse = LensletGrid(pitch_px=pitch, offset_px=offset, shape=shape)
    spots_lit = lit[lit_rows[0] : lit_rows[-1] + 1, lit_cols[0] : lit_cols[-1] + 1].reshape(-1)
    grid = _refined(image, coarse, spots_lit)
    logger.debug("detected %s (periodogram estimate %s)", grid, coarse)
    return grid


def _refined(image: NDArray[np.float64], coarse: LensletGrid, lit: NDArray[np.bool_]) -> LensletGrid:
    """Fit ``col = c0 + p j``, ``row = r0 + p i`` (one pitch) to the lit spots' centroids.

    The periodogram pitch is biased by the pupil envelope (a few 1e-3 pixel, i.e. a tenth of a
    pixel across a 40-lenslet array); the fit over all spots is not."""
    measured = Centroider.build(coarse, image.shape).measure(image)
    use = lit & measured.valid
    if np.count_nonzero(use) < 2:
        return coarse
    rows, cols = coarse.shape
    i, j = np.divmod(np.arange(rows * cols), cols)
    i, j = i[use], j[use]
    if not (i.min() < i.max() or j.min() < j.max()):
        return coarse  # a single spot does not determine the pitch
    zeros, ones = np.zeros(i.size), np.ones(i.size)
    design = np.vstack(
        [np.column_stack([ones, zeros, j + 0.5]), np.column_stack([zeros, ones, i + 0.5])]
    )
    target = np.concatenate([measured.centroids[use, 0], measured.centroids[use, 1]])
    (col0, row0, pitch), *_ = np.linalg.lstsq(design, target, rcond=None)
    residual = (target - design @ np.array([col0, row0, pitch])).reshape(2, -1)
    distance = np.hypot(residual[0], residual[1])
    if distance.max() > _RESIDUAL * pitch:
        raise ValueError(
            f"frame: {int(np.count_nonzero(distance > _RESIDUAL * pitch))} of {distance.size} lit spots lie farther "
            f"than {_RESIDUAL} pitch from the fitted square grid of pitch {pitch:.2f} px (worst {distance.max():.2f} "
            f"px); expected a square lenslet grid (detect_lattice finds hexagonal and turned lattices)"
        )
    refined = LensletGrid(pitch_px=float(pitch), offset_px=(float(col0), float(row0)), shape=coarse.shape)
    try:
        refined.check_fits(image.shape)
    except ValueError:
        return coarse
    return refined


def _fitting_range(spot: float, pitch: float, width: int, size: int) -> tuple[int, int]:
    """First index ``n`` and count of the lenslets centred at ``spot + n * pitch`` whose
    ``width``-pixel windows lie in ``[0, size)`` (the window rule of :class:`LensletGrid`)."""
    n = np.arange(-math.ceil(spot / pitch) - 1, math.ceil((size - spot) / pitch) + 2)
    starts = np.ceil(spot + n * pitch - 0.5 * width - _EDGE_TOL)
    inside = n[(starts >= 0) & (starts + width <= size)]
    if inside.size == 0:
        return 0, 0
    return int(inside[0]), int(inside[-1] - inside[0] + 1)


def _gather_windows(
    image: NDArray, row_starts: NDArray[np.intp], col_starts: NDArray[np.intp], width: int
) -> NDArray:
    """All windows as shape (rows, W, cols, W), for any pitch (a copy)."""
    rows = (row_starts[:, None] + np.arange(width)).reshape(-1)
    gathered = _gather_rows_cols(image, rows, col_starts, width)
    return gathered.reshape(row_starts.size, width, col_starts.size, width)
