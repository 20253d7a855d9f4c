"""Dwell time by bounded linear least squares on an arbitrary set of dwell points.

The matrix form of the removal model (review: Wang et al., Light: Adv. Manuf. 5, 2024; bounded
forms: Wang et al., Opt. Express 27, 15368, 2019): one column per dwell point holding the TIF
placed at that point, one row per clear-aperture pixel, so ``A t`` is the removal in the clear
aperture of dwell ``t``. The problem solved is

    minimise  || A t - p 1 - z ||^2 + (damping * c)^2 || t ||^2
    over      0 <= t <= max_dwell_s,  p free,

``z`` the surface error in the clear aperture, ``p`` a piston (the removal may exceed the error by
a uniform layer: that costs dwell, not figure), ``c`` the median column norm of ``A`` (so the
damping is dimensionless). ``scipy.optimize.lsq_linear`` solves it (trust-region reflective,
``'trf'``, with LSMR on the sparse matrix). Any point set works (a raster, a spiral, a sparse
subset, an odd-shaped aperture), where the FFT solver needs the full pixel grid.

Start point. ``lsq_linear`` starts from the unbounded solution folded into the bounds; for a
deconvolution that solution oscillates wildly, the fold leaves most dwell at the bound, and the
trust-region iterations then crawl (10 % of the error left after 50 iterations on a test where
the exact dwell is known). So the solve starts instead from an early-stopped unbounded LSMR
solution (early stopping regularises), raised by its most negative dwell and clipped to
``max_dwell_s``: raising every point's dwell alike removes a near-uniform layer in the clear
aperture, which the piston absorbs (the observation behind RIFTA's piston step). ``lsq_linear``
takes no start point, so it solves for the change from this start, bounds shifted to match.
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.optimize import lsq_linear
from scipy.sparse.linalg import lsmr

from .._checks import int_at_least, real_at_least
from ._inputs import surface_in_aperture
from .extension import dwell_grid
from .solution import DwellSolution, make_solution
from .tif import ToolInfluence

logger = logging.getLogger(__name__)

DEFAULT_MAX_NONZEROS = 25_000_000
"""Largest TIF matrix built (non-zero entries; ~16 bytes each while it is assembled)."""


def solve_dwell_lsq(
    surface_nm: ArrayLike,
    clear_aperture: ArrayLike,
    tif: ToolInfluence,
    *,
    points_px: ArrayLike | None = None,
    max_dwell_s: float | None = None,
    damping: float = 0.0,
    max_iter: int = 50,
    lsmr_maxiter: int = 20,
    start_iter: int = 200,
    tol: float = 1e-6,
    max_nonzeros: int = DEFAULT_MAX_NONZEROS,
) -> DwellSolution:
    """Non-negative, bounded dwell at the given points by constrained least squares.

    Parameters
    ----------
    surface_nm : array_like, shape (H, W)
        Surface error to remove (nm), finite in the clear aperture (NaN allowed outside).
    clear_aperture : array_like of bool, shape (H, W)
        Where the figure is judged (the matrix rows); not empty.
    tif : ToolInfluence
        The tool model on the same grid.
    points_px : array_like of int, shape (K, 2), optional
        Dwell points as (row, col) pixels, distinct and inside the array; every pixel of the
        dwell grid if None. Points outside the dwell grid cannot touch the clear aperture: they
        get no column and zero dwell (counted in the diagnostics as ``points_outside_grid``).
    max_dwell_s : float, optional
        Upper bound on the dwell at each point (s), > 0; none if None.
    damping : float, optional
        Tikhonov damping (dimensionless, >= 0, default 0): a small value (1e-3..1e-1) trades a
        little residual for a smoother, shorter dwell.
    max_iter : int, optional
        Iterations of the trust-region solver (default 50).
    lsmr_maxiter : int, optional
        LSMR iterations per trust-region step (default 20): each step needs only a rough
        direction, and an uncapped LSMR makes the cost grow with the point count.
    start_iter : int, optional
        LSMR iterations of the unbounded start (default 200; see the module docstring).
    tol : float, optional
        Its relative tolerance on the cost (default 1e-6).
    max_nonzeros : int, optional
        Refuse to build a larger matrix (default 25 million entries): use fewer points.

    Returns
    -------
    DwellSolution
        ``solver="lsq"``; diagnostics: points, points_used, points_outside_grid, nonzeros,
        piston_nm, at_max_dwell, iterations, status, message, damping, max_dwell_s.

    Raises
    ------
    ValueError
        Naming ``surface_nm``, ``clear_aperture``, ``points_px``, ``max_dwell_s``, ``damping``,
        ``max_iter``, ``lsmr_maxiter``, ``start_iter``, ``tol`` or ``max_nonzeros``.

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline.polishing import ToolInfluence, solve_dwell_lsq
    >>> tif = ToolInfluence.gaussian(fwhm_mm=2.0, peak_rate_nm_s=1.0, pixel_mm=0.25)
    >>> rows, cols = np.indices((48, 48)) - 23.5
    >>> aperture = rows**2 + cols**2 < 12**2
    >>> surface = np.where(aperture, 20.0 * (rows**2 + cols**2) / 144.0, np.nan)
    >>> solution = solve_dwell_lsq(surface, aperture, tif, max_dwell_s=5.0)
    >>> bool(solution.dwell_s.max() <= 5.0), bool(solution.rms_nm < 0.1 * np.nanstd(surface))
    (True, True)
    """
    surface, mask = surface_in_aperture(surface_nm, clear_aperture)
    upper = np.inf if max_dwell_s is None else real_at_least(max_dwell_s, "max_dwell_s", 0.0, strict=True, unit="s")
    damp = real_at_least(damping, "damping", 0.0)
    iterations = int_at_least(max_iter, "max_iter", 1)
    inner = int_at_least(lsmr_maxiter, "lsmr_maxiter", 1)
    start_iter = int_at_least(start_iter, "start_iter", 1)
    tolerance = real_at_least(tol, "tol", 0.0, strict=True)
    budget = int_at_least(max_nonzeros, "max_nonzeros", 1)
    grid = dwell_grid(mask, tif)
    points = _points(points_px, grid)
    used = points[grid[points[:, 0], points[:, 1]]]
    if used.shape[0] < points.shape[0]:
        logger.info("%d of %d dwell points lie outside the dwell grid: no dwell there", points.shape[0] - used.shape[0], points.shape[0])
    matrix = _tif_matrix(used, mask, tif, budget)
    target = surface[mask] - surface[mask].mean()
    system, rhs, scale = _system(matrix, target, damp)
    lower_bounds = np.r_[np.zeros(used.shape[0]), -np.inf]
    upper_bounds = np.r_[np.full(used.shape[0], upper), np.inf]
    start = _feasible_start(system, rhs, matrix.shape[0], upper, start_iter)
    fitted = lsq_linear(system, rhs - system @ start, bounds=(lower_bounds - start, upper_bounds - start), method="trf",
                        lsq_solver="lsmr", tol=tolerance, max_iter=iterations, lsmr_tol="auto", lsmr_maxiter=inner)
    solved = start + fitted.x
    dwell_at = np.clip(solved[:-1], 0.0, upper)
    dwell = np.zeros(surface.shape)
    dwell[used[:, 0], used[:, 1]] = dwell_at
    diagnostics = {
        "points": int(points.shape[0]),
        "points_used": int(used.shape[0]),
        "points_outside_grid": int(points.shape[0] - used.shape[0]),
        "nonzeros": int(matrix.nnz),
        "piston_nm": float(solved[-1]),
        "at_max_dwell": int(np.count_nonzero(dwell_at >= upper)) if np.isfinite(upper) else 0,
        "iterations": int(fitted.nit),
        "status": int(fitted.status),
        "message": str(fitted.message),
        "damping": damp,
        "damping_scale": scale,
        "max_dwell_s": None if max_dwell_s is None else upper,
    }
    return make_solution(surface, mask, grid, dwell, tif, "lsq", diagnostics)


def _feasible_start(
    system: sparse.csr_array, rhs: NDArray[np.float64], pixels: int, upper: float, iterations: int
) -> NDArray[np.float64]:
    """An early-stopped unbounded LSMR solution, dwell raised to >= 0 and clipped to ``upper``.

    The piston (last entry) is then the one that zeroes the mean misfit over the ``pixels``
    clear-aperture rows (the damping rows, if any, follow them).
    """
    free = lsmr(system, rhs, maxiter=iterations)[0]
    dwell = np.minimum(free[:-1] - min(float(free[:-1].min()), 0.0), upper)
    start = np.r_[dwell, 0.0]
    start[-1] = float(np.mean((system @ start - rhs)[:pixels]))
    return start


def _points(points_px: ArrayLike | None, grid: NDArray[np.bool_]) -> NDArray[np.intp]:
    """The dwell points as an (K, 2) int array, checked: integers, inside the array, distinct."""
    if points_px is None:
        return np.argwhere(grid)
    points = np.asarray(points_px)
    if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] == 0:
        raise ValueError(f"points_px: expected a (K, 2) array of (row, col) pixels with K >= 1, got shape {points.shape}")
    if not np.issubdtype(points.dtype, np.integer):
        raise ValueError(f"points_px: expected integer pixel indices, got dtype {points.dtype}")
    inside = (points[:, 0] >= 0) & (points[:, 0] < grid.shape[0]) & (points[:, 1] >= 0) & (points[:, 1] < grid.shape[1])
    if not inside.all():
        first = points[np.argmin(inside)]
        raise ValueError(f"points_px: expected pixels inside the {grid.shape} array, got ({first[0]}, {first[1]})")
    if np.unique(points, axis=0).shape[0] != points.shape[0]:
        raise ValueError("points_px: expected distinct points, got a point listed twice")
    return points.astype(np.intp)


def _tif_matrix(points: NDArray[np.intp], mask: NDArray[np.bool_], tif: ToolInfluence, budget: int) -> sparse.csc_array:
    """Sparse (clear-aperture pixels, points): column k is the TIF at point k, on the aperture rows."""
    row_of = np.full(mask.shape, -1, dtype=np.int64)
    row_of[mask] = np.arange(np.count_nonzero(mask))
    radius = tif.radius_px
    offsets = np.argwhere(tif.footprint) - radius
    expected = offsets.shape[0] * points.shape[0]
    if expected > budget and _count_entries(points, offsets, mask) > budget:
        raise ValueError(f"points_px: the TIF matrix would hold more than max_nonzeros = {budget} entries; "
                         "expected fewer dwell points (e.g. every 2nd or 3rd pixel)")
    padded = np.pad(row_of, radius, constant_values=-1)
    rows, cols, values = [], [], []
    for d_row, d_col in offsets:
        hit = padded[points[:, 0] + d_row + radius, points[:, 1] + d_col + radius]
        keep = np.nonzero(hit >= 0)[0]
        rows.append(hit[keep].astype(np.int32))
        cols.append(keep.astype(np.int32))
        values.append(np.full(keep.size, tif.kernel_nm_per_s[d_row + radius, d_col + radius]))
    shape = (int(np.count_nonzero(mask)), points.shape[0])
    return sparse.csc_array((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=shape)


def _count_entries(points: NDArray[np.intp], offsets: NDArray[np.intp], mask: NDArray[np.bool_]) -> int:
    """How many (pixel, point) pairs fall inside the aperture, without building anything."""
    radius = int(np.abs(offsets).max()) if offsets.size else 0
    padded = np.pad(mask, radius)
    return int(sum(np.count_nonzero(padded[points[:, 0] + dr + radius, points[:, 1] + dc + radius]) for dr, dc in offsets))


def _system(
    matrix: sparse.csc_array, target: NDArray[np.float64], damping: float
) -> tuple[sparse.csr_array, NDArray[np.float64], float]:
    """Append the piston column (-1: removal = error + p) and the damping rows."""
    pixels, count = matrix.shape
    norms = np.sqrt(np.asarray(matrix.multiply(matrix).sum(axis=0)).ravel())
    scale = float(np.median(norms[norms > 0])) if np.any(norms > 0) else 1.0
    piston = sparse.csc_array(-np.ones((pixels, 1)))
    system = sparse.hstack([matrix, piston], format="csr")
    rhs = target
    if damping > 0:
        rows = sparse.hstack([sparse.eye_array(count) * (damping * scale), sparse.csr_array((count, 1))])
        system = sparse.vstack([system, rows], format="csr")
        rhs = np.r_[target, np.zeros(count)]
    return system, rhs, scale
