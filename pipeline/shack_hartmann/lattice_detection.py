"""Finding the lenslet lattice, square or hexagonal, from the spots of a frame, or refusing with the reason.

Steps of :func:`detect_lattice`:

1. Spots: local maxima of the frame smoothed by a Gaussian of 1 px, more than 6 noise sigmas
   (the median absolute deviation of the smoothed frame) above its median, and at least a
   quarter as high as the 90th percentile of those maxima; plateaus count once.
2. Nearest neighbours (k-d tree): every spot's nearest-neighbour distance must lie within
   10 % of their median ``d`` for 90 % of the spots, else the spots are not one lattice (random
   spots, two pitches superimposed). The vectors to the neighbours within ``[0.8, 1.2] d`` are
   folded to ``[0, 180)`` degrees; their 4-fold order ``|<exp(4 i theta)>|`` is near 1 for a
   square lattice, the 6-fold ``|<exp(6 i theta)>|`` for a hexagonal one (the other is near
   0); neither above 0.9 is refused. The argument of that mean gives the orientation.
3. Indices and fit: each spot gets the integer site ``(n1, n2)`` nearest to it on the lattice
   of step ``d`` at that orientation, starting at the spot nearest the spots' centroid; then
   the similarity transform ``p = o + s R(phi) (n1 e1 + n2 e2)`` (``e1, e2`` the unit basis of
   the kind) is fitted by linear least squares (unknowns ``o``, ``s cos phi``, ``s sin phi``),
   the sites re-assigned and the fit repeated. Only a similarity is fitted, so what the
   lenslets cannot do (a shear, unequal pitches) stays in the residual, and the result is a
   lattice of the kind by construction.
4. Sub-pixel: the spots are centroided in their lenslet windows
   (:class:`~wavestack.pipeline.shack_hartmann.centroids.Centroider`) and the fit repeated on
   the centroids. Refused unless every spot lies within ``0.25`` pitch of its site and no two
   spots share a site.

The 0.25-pitch residual bound is what a usable spot pattern needs anyway: a spot farther from
its lenslet centre leaves the window the centroider gives it (half-width ``0.37`` pitch for a
hexagonal lattice). The order-parameter and spread thresholds are choices with a wide margin
on both sides: a lattice measured to a fraction of a pixel gives orders above 0.99 and spreads
of a few per cent, random spots orders below 0.3 and spreads of tens of per cent.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import scipy.ndimage
import scipy.spatial
from numpy.typing import ArrayLike, NDArray

from .centroids import Centroider, camera_frame
from .lattice import _UNIT, LatticeKind, LensletLattice

__all__ = ["detect_lattice"]

logger = logging.getLogger(__name__)

_MIN_SPOTS = 9  # fewer spots do not determine a lattice with a residual check
_SIGMAS = 6.0  # a spot peak stands this many noise sigmas above the background
_PEAK_FRACTION = 0.25  # ... and at this fraction of the typical (90th percentile) peak
_NN_SPREAD = 0.10  # nearest-neighbour distances within this fraction of their median ...
_NN_INSIDE = 0.90  # ... for at least this fraction of the spots
_ORDER = 0.9  # 4- or 6-fold orientational order needed
_RESIDUAL = 0.25  # every spot within this fraction of the pitch of its lattice site


def detect_lattice(frame: ArrayLike) -> LensletLattice:
    """Find the square or hexagonal lenslet lattice of a spot frame (ideally a reference frame).

    Parameters
    ----------
    frame : array_like, shape (rows, cols)
        Camera frame, any real dtype and memory layout, background roughly uniform.

    Returns
    -------
    LensletLattice
        Kind, basis (pitch and orientation), origin and one site per spot whose window fits in
        the frame, ordered row-major in the site indices (``n2``, then ``n1``).

    Raises
    ------
    ValueError
        One line giving the reason: the frame is not a finite real 2-D array; fewer than 9
        spots; the nearest-neighbour distances spread (not one lattice); the neighbour
        directions are neither 90 nor 60 degrees apart; or a spot lies more than a quarter
        pitch from its fitted site, or two spots share one.

    Notes
    -----
    The lattice is placed on the *spots*: on an aberrated frame its origin carries the mean
    tilt and its pitch the defocus, so detect on a reference frame, or fix the pitch from the
    lenslet description. Method and thresholds: module notes.

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[:120, :140]
    >>> frame = np.zeros((120, 140))
    >>> for n2 in range(-2, 3):
    ...     for n1 in range(-3, 4):
    ...         col, row = 70 + 16 * n1 + 8 * n2, 60 + 8 * np.sqrt(3) * n2
    ...         frame += np.exp(-((cols - col) ** 2 + (rows - row) ** 2) / 3.0)
    >>> lattice = detect_lattice(frame)
    >>> lattice.kind, round(lattice.pitch_px, 2), lattice.count
    ('hexagonal', 16.0, 35)
    """
    image = camera_frame(frame).astype(np.float64, copy=False)
    if not np.all(np.isfinite(image)):
        raise ValueError("frame must be finite, got NaN or infinite pixels")
    points = _spot_peaks(image)
    kind, step, orientation = _classify(points)
    lattice = _fit(points, kind, step, orientation, image.shape)
    measured = Centroider.build(lattice, image.shape).measure(image)
    if not measured.valid.all():
        lattice = lattice.with_sites(lattice.sites[measured.valid])
    refined = _fit(measured.centroids[measured.valid], kind, lattice.pitch_px, lattice.orientation_deg, image.shape)
    logger.debug("detected %s lattice, pitch %.4f px at %.3f deg, %d lenslets", kind, refined.pitch_px,
                 refined.orientation_deg, refined.count)
    return refined


def _spot_peaks(image: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(col, row)`` of the spot peaks, pixels (one per plateau), shape (N, 2)."""
    smoothed = scipy.ndimage.gaussian_filter(image, 1.0)
    background = float(np.median(smoothed))
    noise = 1.4826 * float(np.median(np.abs(smoothed - background)))
    maxima = smoothed == scipy.ndimage.maximum_filter(smoothed, size=5)
    candidates = maxima & (smoothed > background + max(_SIGMAS * noise, 1e-9 * max(abs(background), 1.0)))
    if not candidates.any():
        raise ValueError("frame: no spots above the background; expected a Shack-Hartmann spot frame")
    typical = float(np.percentile(smoothed[candidates], 90)) - background
    peaks = candidates & (smoothed > background + _PEAK_FRACTION * typical)
    labels, count = scipy.ndimage.label(peaks, structure=np.ones((3, 3)))
    centres = np.asarray(scipy.ndimage.center_of_mass(peaks, labels, np.arange(1, count + 1)), dtype=np.float64)
    if count < _MIN_SPOTS:
        raise ValueError(f"frame: found {count} spots; expected at least {_MIN_SPOTS} to determine a lenslet lattice")
    return centres.reshape(-1, 2)[:, ::-1].copy()


def _classify(points: NDArray[np.float64]) -> tuple[LatticeKind, float, float]:
    """Kind, neighbour distance (px) and orientation (deg) from the nearest-neighbour vectors."""
    distances, neighbours = scipy.spatial.cKDTree(points).query(points, k=min(7, len(points)))
    nearest = distances[:, 1]
    step = float(np.median(nearest))
    inside = float(np.mean(np.abs(nearest / step - 1.0) <= _NN_SPREAD))
    if inside < _NN_INSIDE:
        low, high = np.percentile(nearest, [5, 95])
        raise ValueError(
            f"frame: nearest-neighbour distances of the spots spread from {low:.1f} to {high:.1f} px (5-95 %); "
            f"expected one lattice pitch (random spots or two pitches superimposed?)"
        )
    near = (distances[:, 1:] >= 0.8 * step) & (distances[:, 1:] <= 1.2 * step)
    vectors = points[neighbours[:, 1:][near]] - np.repeat(points, near.sum(axis=1), axis=0)
    theta = np.arctan2(vectors[:, 1], vectors[:, 0])
    orders = {fold: np.mean(np.exp(1j * fold * theta)) for fold in (4, 6)}
    square, hexagonal = abs(orders[4]), abs(orders[6])
    if max(square, hexagonal) < _ORDER:
        raise ValueError(
            f"frame: spot neighbours are neither 90 deg apart (square order {square:.2f}) nor 60 deg apart "
            f"(hexagonal order {hexagonal:.2f}); expected a square or hexagonal lenslet lattice (order >= {_ORDER})"
        )
    fold = 6 if hexagonal > square else 4
    lengths = np.hypot(vectors[:, 0], vectors[:, 1])
    return ("hexagonal" if fold == 6 else "square"), float(lengths.mean()), math.degrees(np.angle(orders[fold]) / fold)


def _fit(
    points: NDArray[np.float64], kind: LatticeKind, step: float, orientation_deg: float, frame_shape: tuple[int, int]
) -> LensletLattice:
    """Sites of the spots and the similarity-transformed lattice fitted to them (module notes, step 3)."""
    angle = math.radians(orientation_deg)
    rotation = np.array([[math.cos(angle), math.sin(angle)], [-math.sin(angle), math.cos(angle)]])
    basis = step * _UNIT[kind] @ rotation  # rows a1, a2 as (d_col, d_row)
    origin = points[np.argmin(np.hypot(*(points - points.mean(axis=0)).T))]
    for _ in range(2):
        sites = np.rint((points - origin) @ np.linalg.inv(basis)).astype(np.intp)
        origin, basis = _similarity(points, sites, kind)
    residual = points - (origin + sites @ basis)
    distance = np.hypot(residual[:, 0], residual[:, 1])
    pitch = float(np.hypot(*basis[0]))
    far = distance > _RESIDUAL * pitch
    if far.any():
        raise ValueError(
            f"frame: {int(far.sum())} of {len(points)} spots lie farther than {_RESIDUAL} pitch from the fitted "
            f"{kind} lattice of pitch {pitch:.2f} px (worst {distance.max():.2f} px); expected one {kind} lattice"
        )
    if np.unique(sites, axis=0).shape[0] != sites.shape[0]:
        raise ValueError(f"frame: two spots fall on one site of the fitted {kind} lattice; expected one lattice")
    lattice = LensletLattice(kind, tuple(map(tuple, basis)), tuple(origin), sites[np.lexsort(sites.T)])
    rows, cols, width = lattice.window_starts()
    fits = (rows >= 0) & (cols >= 0) & (rows + width <= frame_shape[0]) & (cols + width <= frame_shape[1])
    if not fits.all():
        logger.info("%d spots at the frame edge left out: their windows leave the frame", int((~fits).sum()))
        if fits.sum() < _MIN_SPOTS:
            raise ValueError(f"frame: only {int(fits.sum())} spots have whole windows; expected at least {_MIN_SPOTS}")
        lattice = lattice.with_sites(lattice.sites[fits])
    return lattice


def _similarity(
    points: NDArray[np.float64], sites: NDArray[np.intp], kind: LatticeKind
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least-squares origin and basis of ``p = o + s R(phi) (n @ unit)``: linear in ``o, s cos, s sin``."""
    unit = sites @ _UNIT[kind]  # (N, 2) lattice points of unit pitch, unrotated
    ones, zeros = np.ones(len(points)), np.zeros(len(points))
    # col = o_c + a u - b v, row = o_r + b u + a v with a = s cos phi, b = s sin phi
    design = np.vstack([np.column_stack([ones, zeros, unit[:, 0], -unit[:, 1]]),
                        np.column_stack([zeros, ones, unit[:, 1], unit[:, 0]])])
    (o_col, o_row, a, b), *_ = np.linalg.lstsq(design, np.concatenate([points[:, 0], points[:, 1]]), rcond=None)
    transform = np.array([[a, b], [-b, a]])  # row vector u @ transform = (a u - b v, b u + a v)
    return np.array([o_col, o_row]), _UNIT[kind] @ transform
