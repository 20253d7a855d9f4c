"""The dwell grid, and the surface error extended beyond the clear aperture onto it.

The tool polishes a clear-aperture pixel from every dwell point within its radius, so the dwell
grid must reach past the aperture edge by at least the TIF radius on every side (Wang et al.,
"RIFTA", Sci. Rep. 10, 8135, 2020). A solver that works on the whole grid (the FFT inverse filter)
also needs a surface there: what it is told to remove beyond the edge decides whether the edge is
polished or rolled (Wang et al., surface extension, and RISE, Opt. Express 29, 15114, 2021, who
compare zero, Gaussian, nearest-neighbour, smooth and Gerchberg extensions).
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
from numpy.polynomial import legendre
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import distance_transform_edt

from .._checks import positive_float
from ._inputs import clear_aperture_mask, surface_in_aperture
from .tif import ToolInfluence

logger = logging.getLogger(__name__)

DEFAULT_TREND_DEGREE = 3
"""Total degree of the Legendre trend continued past the edge: enough for power, astigmatism,
coma and trefoil, low enough that its extrapolation over one tool radius stays tame."""


def dwell_grid(clear_aperture: ArrayLike, tif: ToolInfluence) -> NDArray[np.bool_]:
    """The pixels where dwell removes material in the clear aperture: the aperture grown by the TIF.

    A pixel ``p`` is in the grid when the tool dwelling there reaches a clear-aperture pixel, that
    is when ``p + s`` is in the aperture for some offset ``s`` of the TIF footprint (a disc of the
    TIF radius for a Gaussian TIF); the clear aperture itself is always included. Dwell outside
    this grid cannot change the clear aperture, so the solvers keep it zero there. The grid is
    clipped by the array: an aperture closer to the border than the TIF radius loses dwell room
    at that edge (logged).

    Parameters
    ----------
    clear_aperture : array_like of bool, shape (H, W)
    tif : ToolInfluence

    Returns
    -------
    NDArray[np.bool_], shape (H, W)

    Raises
    ------
    ValueError
        Naming ``clear_aperture`` (not boolean 2-D, or empty).

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline.polishing import ToolInfluence, dwell_grid
    >>> tif = ToolInfluence.gaussian(fwhm_mm=1.0, peak_rate_nm_s=1.0, pixel_mm=0.25)
    >>> aperture = np.zeros((21, 21), bool); aperture[10, 10] = True
    >>> grid = dwell_grid(aperture, tif)
    >>> tif.radius_px, int(grid.sum()), bool(np.array_equal(grid[5:16, 5:16], tif.footprint))
    (5, 81, True)
    """
    mask = clear_aperture_mask(clear_aperture)
    footprint = np.ascontiguousarray(tif.footprint, dtype=np.uint8)
    grown = cv2.dilate(mask.astype(np.uint8), footprint, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
    grid = grown | mask
    radius = tif.radius_px
    rows, cols = np.nonzero(mask)
    if rows.min() < radius or cols.min() < radius or rows.max() >= mask.shape[0] - radius or cols.max() >= mask.shape[1] - radius:
        logger.warning("clear aperture lies within the TIF radius (%d px) of the array border: the dwell grid is "
                       "clipped there and that edge cannot be fully corrected", radius)
    return grid


def extend_surface(
    surface_nm: ArrayLike,
    clear_aperture: ArrayLike,
    region: ArrayLike,
    *,
    degree: int = DEFAULT_TREND_DEGREE,
    decay_px: float | None = None,
) -> NDArray[np.float64]:
    """The surface error continued smoothly from the clear aperture over ``region``.

    Method: a low-order trend continued, plus the edge detail faded out. A Legendre polynomial
    of total degree ``degree`` is fitted to the surface over the clear aperture (least squares);
    outside the aperture the value is that trend plus the fit residual of the nearest aperture
    pixel times ``exp(-d^2 / (2 decay_px^2))``, ``d`` the distance (px) to the aperture. So the
    extension is continuous at the edge (value and, through the trend, the low-order slope), the
    mid-spatial detail at the edge is carried about one tool width out, then fades to the trend.

    Why this one: of the extensions compared by Wang et al. (surface extension; RISE, Opt.
    Express 29, 15114, 2021), zero and nearest-neighbour extensions leave a step or a kink in
    the slope at the edge, which a deconvolution answers with ringing and a rolled edge; the
    smooth extensions do not. Gerchberg's band-limited extrapolation is smooth too but iterative
    (a pair of FFTs per iteration, tens of iterations), needs a band limit chosen, and diverges
    slowly away from the edge; the trend-plus-fade here is closed-form, one pass, and cannot
    diverge (the fade bounds the detail, the low degree bounds the trend over a tool radius).

    Parameters
    ----------
    surface_nm : array_like, shape (H, W)
        Surface error (nm), finite inside the clear aperture (anything, NaN too, outside).
    clear_aperture : array_like of bool, shape (H, W)
        Where the surface is known; not empty. Kept as given there.
    region : array_like of bool, shape (H, W)
        Where to extend to (usually :func:`dwell_grid`).
    degree : int, optional
        Total degree of the trend (default 3; lowered when the aperture has too few pixels).
    decay_px : float, optional
        Fade length of the edge detail (px); default the largest distance of ``region`` from
        the aperture (the TIF radius for the dwell grid: the detail is at exp(-1/2) ~ 61 % at
        the grid's far edge, which kept the edge band's residual lowest in our tests).

    Returns
    -------
    NDArray[np.float64], shape (H, W)
        The surface in the clear aperture, the extension in the rest of ``region``, NaN
        elsewhere.

    Raises
    ------
    ValueError
        Naming ``surface_nm``, ``clear_aperture``, ``region``, ``degree`` or ``decay_px``.
    """
    surface, mask = surface_in_aperture(surface_nm, clear_aperture)
    where = np.asarray(region)
    if where.dtype != np.bool_ or where.shape != surface.shape:
        raise ValueError(f"region: expected a boolean array of shape {surface.shape}, got {where.dtype} {where.shape}")
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree < 0:
        raise ValueError(f"degree: expected an integer >= 0, got {degree!r}")
    trend = _legendre_trend(surface, mask, int(degree))
    extended = np.full(surface.shape, np.nan)
    extended[mask] = surface[mask]
    outside = where & ~mask
    if not outside.any():
        return extended
    distance, (near_r, near_c) = distance_transform_edt(~mask, return_indices=True)
    fade = positive_float(decay_px, "decay_px") if decay_px is not None else max(float(distance[outside].max()), 1.0)
    detail = (surface - trend)[near_r[outside], near_c[outside]]
    extended[outside] = trend[outside] + detail * np.exp(-(distance[outside] ** 2) / (2.0 * fade**2))
    return extended


def _legendre_trend(surface: NDArray[np.float64], mask: NDArray[np.bool_], degree: int) -> NDArray[np.float64]:
    """The least-squares Legendre polynomial of total degree <= ``degree`` over ``mask``, everywhere."""
    rows, cols = np.nonzero(mask)
    centre_r, centre_c = (rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2
    half = max((rows.max() - rows.min()) / 2, (cols.max() - cols.min()) / 2, 1.0)
    while (degree + 1) * (degree + 2) // 2 > rows.size:
        degree -= 1
    terms = [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]
    grid_r, grid_c = np.indices(surface.shape, dtype=np.float64)
    u, v = (grid_c - centre_c) / half, (centre_r - grid_r) / half

    def columns(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        vx, vy = legendre.legvander(x, degree), legendre.legvander(y, degree)
        return np.stack([vx[..., i] * vy[..., j] for i, j in terms], axis=-1)

    coefficients, *_ = np.linalg.lstsq(columns(u[mask], v[mask]), surface[mask], rcond=None)
    return columns(u, v) @ coefficients
