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

Where the model cannot tell the two parts apart (a thin strip, on which ``rho`` and the
asymmetric terms are nearly dependent) the least-squares solution of smallest norm is taken;
:attr:`RadialModel.rank_deficiency` says how many directions were undetermined.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from numpy.typing import NDArray

from ..zernike import zernike_basis

__all__ = ["RadialModel"]

# Eigenvalues of the normal matrix below this fraction of the largest are undetermined
# directions (the normal matrix squares the design's condition number: 1e-12 here is 1e-6 on the
# columns, which are all of order one).
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
        Highest radial order ``n`` of the asymmetric (``m != 0``) Zernike terms (>= 1).

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[:41, :41]
    >>> x, y = (cols.ravel() - 20) / 20, (20 - rows.ravel()) / 20
    >>> keep = x**2 + y**2 <= 1
    >>> model = RadialModel(x[keep], y[keep], intervals=8, asymmetric_order=4)
    >>> rho2 = x[keep]**2 + y[keep]**2
    >>> symmetric = model.symmetric_part(rho2**2 + 0.3 * x[keep] * y[keep])
    >>> bool(np.allclose(symmetric, rho2**2))
    True
    """

    def __init__(self, x: NDArray[np.float64], y: NDArray[np.float64], *, intervals: int = 32,
                 asymmetric_order: int = 6) -> None:
        u = x * x + y * y
        self._spline = _spline_design(u, intervals)
        modes = [(n, m) for n in range(1, asymmetric_order + 1) for m in range(-n, n + 1, 2) if m != 0]
        self._asymmetric = np.ascontiguousarray(zernike_basis(modes, x, y).T)  # (a, N): one row per term
        spline_gram = (self._spline.T @ self._spline).toarray()
        cross = np.asarray((self._spline.T @ self._asymmetric.T))
        normal = np.block([[spline_gram, cross], [cross.T, self._asymmetric @ self._asymmetric.T]])
        values, vectors = np.linalg.eigh(normal)
        keep = values > _EIGEN_CUTOFF * values[-1]
        self.rank_deficiency = int(np.count_nonzero(~keep))
        self._solve = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
        self._n_spline = spline_gram.shape[0]

    def symmetric_part(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """The fitted radial profile ``f(rho)`` at every pixel, shape (N,), in the values' units."""
        rhs = np.concatenate([self._spline.T @ values, self._asymmetric @ values])
        coefficients = self._solve[: self._n_spline] @ rhs
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
