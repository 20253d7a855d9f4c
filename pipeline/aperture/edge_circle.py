"""Sub-pixel edge points of a round optic and a circle fitted to them with outlier rejection.

For an optic known to be round, interferometer software offers a circle fitted to the detected
edge rather than the pixel mask (e.g. a "fit circle to aperture" mask option): the pupil's centre
and radius then come from hundreds of edge points, not from the outermost few pixels, and a piece
of halo or a dropout at the rim moves them little. This module does that in three steps:

1. **edge points along rays** (:func:`edge_points`): from the centroid of a detected aperture, one
   ray per pixel of perimeter (``round(2 pi R)``, at least 64), the map (smoothed as for detection,
   see :mod:`.levels`) is sampled every ``RAY_STEP_PX`` by bilinear interpolation between 0.7 and
   1.3 equivalent radii. On each ray the edge is the first fall below the half-way level after the
   profile has been above it, located by linear interpolation between the two samples that
   bracket it. Then each ray gets its own levels, the medians of its profile 3 to 12 px (the
   detection's ``edge_margin_px`` to 9 px more) inside and outside that crossing, and the crossing is found again at their midpoint: where a halo
   touches the rim on one side, its level there is higher than the global halo level, and the
   global midpoint would put the edge too far out by a fraction of the edge response (0.84
   sigma for a Gaussian edge falling from 80 to 35 against a global midpoint of 44). Linear interpolation of a smooth edge response near its 50 % point, where the
   response is close to linear, is accurate to a small fraction of the sample step; the
   bilinear sampling of the pixel grid adds an error well below the speckle's.
2. **algebraic fit** (Kasa [1]_): linear least squares for ``x^2 + y^2 + D x + E y + F = 0``, a
   good start, biased towards smaller radii for short arcs but not for a full circle.
3. **geometric fit with rejection**: Gauss-Newton on the orthogonal distances
   ``d_i = |p_i - c| - R`` [2]_, alternated with rejection of points whose residual is more than
   ``k`` (default 3) scaled MADs (``1.4826 MAD``, a consistent estimate of the standard
   deviation for Gaussian residuals [3]_) from the median, until the kept set does not change.
   Dust dropouts at the rim (early crossings) and halo touching the rim (late crossings) are
   what it rejects.

Uncertainty: the covariance of (cx, cy, R) is ``s^2 (J^T J)^-1`` with ``J`` the Jacobian of the
distances and ``s^2 = sum d_i^2 / (n - 3)`` [2]_. That assumes independent residuals; adjacent
rays see the same speckle grain, so the residuals are correlated along the rim, which would make
the formal errors too small. The covariance is therefore multiplied by the integrated
autocorrelation ``tau = 1 + 2 sum_k rho_k`` of the residuals in ray order, summed while
``rho_k > 0`` (Geyer's initial positive sequence [4]_): ``n / tau`` is the effective number of
independent points.

Coordinates: pixel coordinates, ``cx`` a column and ``cy`` a row, like
:meth:`Aperture.enclosing_circle <wavestack.pipeline.aperture.region.Aperture.enclosing_circle>`.

References
----------
.. [1] I. Kasa, "A circle fitting procedure and its error analysis", IEEE Trans. Instrum. Meas.
   25(1), 8-14 (1976).
.. [2] N. Chernov, *Circular and Linear Regression: Fitting Circles and Lines by Least Squares*,
   CRC Press (2010), ch. 4 (geometric fit) and ch. 6 (covariance).
.. [3] P. J. Rousseeuw and C. Croux, "Alternatives to the median absolute deviation", J. Amer.
   Statist. Assoc. 88, 1273-1283 (1993).
.. [4] C. J. Geyer, "Practical Markov chain Monte Carlo", Statistical Science 7(4), 473-483
   (1992).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .detect import DetectedAperture
from .levels import smoothed

__all__ = ["EdgeCircle", "EdgeFitError", "edge_points", "fit_circle", "fit_edge_circle"]

RAY_STEP_PX = 0.25  # sample spacing along each ray, pixels
_SEARCH = (0.7, 1.3)  # search window along each ray, in equivalent radii
_LOCAL_WIDTH_PX = 9.0  # width of the window of each ray's own levels, pixels
_MAD_TO_SIGMA = 1.4826  # MAD of a Gaussian sample / its standard deviation
_MIN_POINTS = 8


class EdgeFitError(ValueError):
    """Too few edge points for a circle (the aperture is not round, or has no clear edge)."""


@dataclass(frozen=True)
class EdgeCircle:
    """A circle fitted to sub-pixel edge points, with its standard uncertainties.

    Attributes
    ----------
    cx, cy : float
        Centre, pixel coordinates (column, row).
    radius : float
        Radius, pixels.
    sigma_cx, sigma_cy, sigma_radius : float
        Standard uncertainties of ``cx``, ``cy``, ``radius``, pixels (see the module notes).
    rms_residual_px : float
        RMS orthogonal distance of the kept points from the circle, pixels.
    points : int
        Edge points kept.
    rejected : int
        Edge points rejected as outliers.
    correlation : float
        The factor ``tau`` the covariance was multiplied by (>= 1).
    """

    cx: float
    cy: float
    radius: float
    sigma_cx: float
    sigma_cy: float
    sigma_radius: float
    rms_residual_px: float
    points: int
    rejected: int
    correlation: float

    def mask(self, shape: tuple[int, int]) -> NDArray[np.bool_]:
        """Pixels whose centres lie inside the circle (distance < radius), shape ``shape``."""
        rows, cols = np.ogrid[: shape[0], : shape[1]]
        return (cols - self.cx) ** 2 + (rows - self.cy) ** 2 < self.radius**2


def edge_points(
    values: NDArray, mask: NDArray[np.bool_], level: float, margin_px: float = 3.0
) -> NDArray[np.float64]:
    """Sub-pixel crossings of ``level`` along rays from the centroid of ``mask``.

    Parameters
    ----------
    values : NDArray, shape (rows, cols)
        The (smoothed) map, NaN where there is no data.
    mask : NDArray[np.bool_], shape (rows, cols)
        Detected aperture; its centroid is the origin of the rays and ``sqrt(area / pi)`` the
        equivalent radius that sets the search window.
    level : float
        The edge level (half way between disk and halo), map units.
    margin_px : float, optional
        Each ray's own levels are the medians ``margin_px`` to ``margin_px + 9`` px either side of
        its first crossing (default 3; at least the half-width of the edge response).

    Returns
    -------
    NDArray[np.float64], shape (K, 2)
        Edge points (column, row) in ray order (counter-clockwise on the screen), one per ray
        that has a crossing inside the window and inside the frame.
    """
    rows, cols = np.nonzero(mask)
    cy, cx = float(rows.mean()), float(cols.mean())
    radius = math.sqrt(rows.size / math.pi)
    count = max(64, int(round(2.0 * math.pi * radius)))
    theta = np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    r = np.arange(_SEARCH[0] * radius, _SEARCH[1] * radius, RAY_STEP_PX)
    map_x = (cx + np.outer(np.cos(theta), r)).astype(np.float32)
    map_y = (cy - np.outer(np.sin(theta), r)).astype(np.float32)
    profiles = cv2.remap(np.asarray(values, dtype=np.float32), map_x, map_y, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    idx, dist = _first_fall(profiles, np.full(count, level, dtype=np.float32), r, 0)
    # second pass: each ray's own levels (medians 3 to 12 px either side of its first crossing),
    # and its first fall below their midpoint from 3 px inside that crossing
    window = (margin_px, margin_px + _LOCAL_WIDTH_PX)
    levels = _local_levels(profiles[idx], r, dist, window)
    good = np.isfinite(levels)
    idx, dist, levels = idx[good], dist[good], levels[good]
    start = np.searchsorted(r, dist - margin_px)
    found, refined = _first_fall(profiles[idx], levels, r, start)
    idx, dist = idx[found], refined
    return np.column_stack((cx + dist * np.cos(theta[idx]), cy - dist * np.sin(theta[idx])))


def _first_fall(
    profiles: NDArray[np.float32], level: NDArray[np.float32], r: NDArray[np.float64],
    start: NDArray[np.intp] | int,
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Rays (indices) with a first fall below ``level`` at or after ``start``, and its distance."""
    column = np.arange(profiles.shape[1])[None, :]
    begin = np.broadcast_to(np.asarray(start), (profiles.shape[0],))[:, None]
    above = (profiles >= level[:, None]) & (column >= begin)
    below = profiles < level[:, None]  # NaN is neither
    fall = np.maximum.accumulate(above, axis=1) & ~above & (column >= begin)
    j = np.argmax(fall, axis=1)
    ok = fall.any(axis=1) & (j > 0)
    rows = np.flatnonzero(ok)
    ok[rows] = below[rows, j[rows]]  # the first sample past the edge must be data, not outside the frame
    rows = np.flatnonzero(ok)
    j = j[rows]
    p0, p1 = profiles[rows, j - 1].astype(np.float64), profiles[rows, j].astype(np.float64)
    return rows, r[j - 1] + (p0 - level[rows]) / (p0 - p1) * RAY_STEP_PX


def _local_levels(
    profiles: NDArray[np.float32], r: NDArray[np.float64], dist: NDArray[np.float64],
    window: tuple[float, float],
) -> NDArray[np.float32]:
    """Midpoint of each ray's medians ``window`` px inside and outside ``dist`` (NaN if either is empty)."""
    offset = r[None, :] - dist[:, None]
    inner = (offset >= -window[1]) & (offset <= -window[0])
    outer = (offset >= window[0]) & (offset <= window[1])
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rays give NaN, dropped by the caller
        disk = np.nanmedian(np.where(inner, profiles, np.nan), axis=1)
        halo = np.nanmedian(np.where(outer, profiles, np.nan), axis=1)
    return (0.5 * (disk + halo)).astype(np.float32)


def _kasa(points: NDArray[np.float64]) -> tuple[float, float, float]:
    x, y = points[:, 0], points[:, 1]
    design = np.column_stack((x, y, np.ones_like(x)))
    (d, e, f), *_ = np.linalg.lstsq(design, -(x * x + y * y), rcond=None)
    cx, cy = -d / 2.0, -e / 2.0
    return float(cx), float(cy), float(math.sqrt(max(cx * cx + cy * cy - f, 0.0)))


def _geometric(points: NDArray[np.float64], start: tuple[float, float, float]) -> NDArray[np.float64]:
    """Gauss-Newton on orthogonal distances; returns (cx, cy, R)."""
    params = np.array(start, dtype=np.float64)
    for _ in range(20):
        dx, dy = points[:, 0] - params[0], points[:, 1] - params[1]
        dist = np.hypot(dx, dy)
        jac = np.column_stack((-dx / dist, -dy / dist, -np.ones_like(dist)))
        step, *_ = np.linalg.lstsq(jac, -(dist - params[2]), rcond=None)
        params += step
        if np.max(np.abs(step)) < 1e-9 * max(1.0, params[2]):
            break
    return params


def _integrated_autocorrelation(residuals: NDArray[np.float64]) -> float:
    """``1 + 2 sum rho_k`` over the initial positive sequence of autocorrelations (>= 1)."""
    centred = residuals - residuals.mean()
    var = float(np.dot(centred, centred))
    if var == 0.0:
        return 1.0
    tau = 1.0
    for lag in range(1, centred.size // 2):
        rho = float(np.dot(centred[:-lag], centred[lag:])) / var
        if rho <= 0.0:
            break
        tau += 2.0 * rho
    return tau


def fit_circle(points: ArrayLike, *, reject_mads: float = 3.0) -> EdgeCircle:
    """Fit a circle to edge points with iterative outlier rejection (see the module notes).

    Parameters
    ----------
    points : array_like, shape (K, 2)
        Edge points (column, row), pixels, in order along the edge (for the correlation factor).
    reject_mads : float, optional
        Points farther than this many scaled MADs from the median residual are rejected.

    Returns
    -------
    EdgeCircle

    Raises
    ------
    EdgeFitError
        If fewer than 8 points are given or remain.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    >>> pts = np.column_stack((50 + 20 * np.cos(t), 40 + 20 * np.sin(t)))
    >>> pts[0] = (90, 40)  # one outlier
    >>> c = fit_circle(pts)
    >>> round(c.cx, 6), round(c.cy, 6), round(c.radius, 6), c.rejected
    (50.0, 40.0, 20.0, 1)
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] < _MIN_POINTS:
        raise EdgeFitError(f"{pts.shape[0]} edge points; expected at least {_MIN_POINTS} for a circle")
    keep = np.ones(pts.shape[0], dtype=bool)
    params = np.array(_kasa(pts))
    for _ in range(20):
        params = _geometric(pts[keep], tuple(params))
        res = np.hypot(pts[:, 0] - params[0], pts[:, 1] - params[1]) - params[2]
        centre = np.median(res[keep])
        scale = _MAD_TO_SIGMA * np.median(np.abs(res[keep] - centre))
        new_keep = np.abs(res - centre) <= reject_mads * scale if scale > 0 else keep
        if new_keep.sum() < _MIN_POINTS:
            raise EdgeFitError(f"only {int(new_keep.sum())} edge points agree on a circle")
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return _with_uncertainty(pts[keep], params, int((~keep).sum()))


def _with_uncertainty(pts: NDArray[np.float64], params: NDArray[np.float64], rejected: int) -> EdgeCircle:
    dx, dy = pts[:, 0] - params[0], pts[:, 1] - params[1]
    dist = np.hypot(dx, dy)
    res = dist - params[2]
    jac = np.column_stack((-dx / dist, -dy / dist, -np.ones_like(dist)))
    dof = max(pts.shape[0] - 3, 1)
    tau = _integrated_autocorrelation(res)
    cov = float(np.dot(res, res)) / dof * tau * np.linalg.inv(jac.T @ jac)
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return EdgeCircle(
        cx=float(params[0]), cy=float(params[1]), radius=float(params[2]),
        sigma_cx=float(sigma[0]), sigma_cy=float(sigma[1]), sigma_radius=float(sigma[2]),
        rms_residual_px=float(np.sqrt(np.mean(res**2))), points=int(pts.shape[0]),
        rejected=rejected, correlation=tau,
    )


def fit_edge_circle(
    signal_map: ArrayLike, detected: DetectedAperture, *, smooth_sigma_px: float = 1.5,
    reject_mads: float = 3.0, margin_px: float = 3.0,
) -> EdgeCircle:
    """Circle through the sub-pixel half-way edge of a detected round aperture.

    Parameters
    ----------
    signal_map : array_like, shape (rows, cols)
        The map the aperture was detected in (modulation), NaN where there is no data.
    detected : DetectedAperture
        Its detection; the edge level is ``detected.threshold`` (half way between the disk and
        halo levels under the default ``"midpoint"`` rule).
    smooth_sigma_px : float, optional
        Gaussian smoothing before sampling, pixels (as in detection; it does not move a half-way
        edge, see :mod:`.levels`).
    reject_mads : float, optional
        Outlier rejection, scaled MADs.
    margin_px : float, optional
        Half-width of the edge response, pixels (the detection's ``edge_margin_px``).

    Returns
    -------
    EdgeCircle

    Raises
    ------
    EdgeFitError
        If the rays find too few edge points (e.g. a long thin aperture, whose centroid rays
        mostly leave the window).
    """
    values = smoothed(np.asarray(signal_map, dtype=np.float32), smooth_sigma_px)
    points = edge_points(values, detected.aperture.mask, detected.threshold, margin_px)
    return fit_circle(points, reject_mads=reject_mads)
