"""The rotationally symmetric part of a map on any aperture: a radial profile fitted jointly with
the non-rotationally-symmetric terms.

On a full circle or annulus the rotationally symmetric part of a map is its azimuthal mean at
each radius. On an aperture whose rings are incomplete (a rounded rectangle, a D shape, a part
with drop-outs) the azimuthal mean of an arc also holds whatever the asymmetric terms add up to
on that arc, so it is not the symmetric part. Here the map is modelled as

    f(rho) + sum_k a_k Z_k(x, y)

with ``f`` a cubic B-spline in ``u = rho^2`` (smooth through the axis, uniform knots over the
radii present) and ``Z_k`` the circle Zernike terms with ``m != 0`` up to a radial order, fitted
together by least squares on the measured pixels. On complete rings the asymmetric terms are
orthogonal to every radial function and ``f`` is the azimuthal mean, ring by ring; on incomplete
rings the joint fit keeps asymmetric content out of ``f``. A cubic spline in ``u`` reproduces
every polynomial of degree <= 3 in ``rho^2`` exactly (the sphere, primary and secondary
spherical), so surfaces built from such terms are decomposed exactly.

The narrower the rings' arcs, the more an asymmetric term of high order looks radial on them,
and the joint fit then splits noise between the two parts at will (on a 2.6:1 rounded rectangle
with all terms to order 6 the condition number of the fit is 1e7, and 2 nm of white noise moves
RSI by tens to hundreds of nm, past the irregularity itself). The order of the asymmetric terms is therefore the highest, up to the
one asked for, at which the condition number of the joint fit (columns scaled to unit norm)
stays within :data:`MAX_CONDITION`: order 6 on circles, annuli and disks with an off-axis hole
(about 50), 3 on a 2.6:1 rounded rectangle, 1 on a 7:1 strip, none where even tilt is
indistinguishable from a radial profile. :attr:`RadialModel.asymmetric_order` says which.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from numpy.typing import NDArray

from ..zernike import zernike_basis

__all__ = ["MAX_CONDITION", "RadialModel"]

#: The largest condition number of the joint fit (columns of unit norm) an asymmetric order may
#: bring; the spline alone has about 45 on a full disk.
MAX_CONDITION = 1e3
# Eigenvalues of the normal matrix below this fraction of the largest are undetermined
# directions (an empty knot interval): the least-squares solution of smallest norm is taken.
_EIGEN_CUTOFF = 1e-12


class RadialModel:
    """The joint fit of a radial profile and asymmetric Zernike terms, factorised once per pixel set.

    Parameters
    ----------
    x, y : ndarray, shape (N,)
        Pixel coordinates in units of the test area's radius (x right, y up), centred on the axis
        of symmetry.
    intervals : int
        Knot intervals of the spline in ``u = rho^2`` over the radii present (>= 1).
    asymmetric_order : int
        Highest radial order ``n`` of the asymmetric (``m != 0``) Zernike terms (>= 0); lowered
        until the fit's condition number is within ``max_condition``.
    max_condition : float
        :data:`MAX_CONDITION` unless given.

    Attributes
    ----------
    asymmetric_order : int
        The order used.
    condition : float
        The condition number of the joint fit at that order (columns of unit norm).

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[:41, :41]
    >>> x, y = (cols.ravel() - 20) / 20, (20 - rows.ravel()) / 20
    >>> keep = x**2 + y**2 <= 1
    >>> model = RadialModel(x[keep], y[keep], intervals=8, asymmetric_order=4)
    >>> rho2 = x[keep]**2 + y[keep]**2
    >>> symmetric = model.symmetric_part(rho2**2 + 0.3 * x[keep] * y[keep])
    >>> bool(np.allclose(symmetric, rho2**2)), model.asymmetric_order
    (True, 4)
    """

    def __init__(self, x: NDArray[np.float64], y: NDArray[np.float64], *, intervals: int = 32,
                 asymmetric_order: int = 6, max_condition: float = MAX_CONDITION) -> None:
        self._spline = _spline_design(x * x + y * y, intervals)
        self._spline_t = self._spline.T.tocsr()
        spline_gram = (self._spline_t @ self._spline).toarray()
        for order in range(asymmetric_order, -1, -1):
            modes = [(n, m) for n in range(1, order + 1) for m in range(-n, n + 1, 2) if m != 0]
            asymmetric = np.ascontiguousarray(zernike_basis(modes, x, y).T) if modes else np.zeros((0, x.size))
            cross = np.asarray(self._spline_t @ asymmetric.T)
            normal = np.block([[spline_gram, cross], [cross.T, asymmetric @ asymmetric.T]])
            scale = 1.0 / np.sqrt(np.maximum(np.diag(normal), np.finfo(float).tiny))
            values, vectors = np.linalg.eigh(normal * scale[:, None] * scale[None, :])
            keep = values > _EIGEN_CUTOFF * values[-1]
            condition = float(values[-1] / values[keep][0])
            if condition <= max_condition or order == 0:
                break
        self.asymmetric_order = order
        self.condition = condition
        self.rank_deficiency = int(np.count_nonzero(~keep))
        self._asymmetric = asymmetric
        inverse = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
        self._solve = (inverse * scale[:, None] * scale[None, :])[: spline_gram.shape[0]]

    def symmetric_part(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """The fitted radial profile ``f(rho)`` at every pixel, shape (N,), in the values' units."""
        coefficients = self._solve @ np.concatenate([self._spline_t @ values, self._asymmetric @ values])
        return self._spline @ coefficients


def _spline_design(u: NDArray[np.float64], intervals: int) -> sparse.csr_matrix:
    """Uniform cubic B-splines in ``u`` over ``[u.min(), u.max()]``, shape (N, intervals + 3), 4 per row."""
    if intervals < 1:
        raise ValueError(f"intervals must be an integer >= 1, got {intervals!r}")
    low, high = float(u.min()), float(u.max())
    step = (high - low) / intervals or 1.0
    scaled = (u - low) / step
    first = np.clip(np.floor(scaled).astype(np.int64), 0, intervals - 1)
    t = scaled - first
    weights = np.column_stack([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3]) / 6
    columns = first[:, None] + np.arange(4)
    rows = np.repeat(np.arange(u.size), 4)
    return sparse.csr_matrix((weights.ravel(), (rows, columns.ravel())), shape=(u.size, intervals + 3))
