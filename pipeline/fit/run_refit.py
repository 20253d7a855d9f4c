"""The whole refit of a small frame in one compiled call: moments, centring, solve, coefficients.

For the fitters whose frames the run pass serves (:mod:`~wavestack.pipeline.fit.run_moments`:
degree <= 7, strips up to 512 columns) and that remove no physical terms, a refit is

1. the shift ``s`` (the mean of each strip's first fitted sample, as
   :class:`~wavestack.pipeline.fit.moment_projection.MomentProjection` takes it), the moments of
   ``w - s`` and ``|w - s|^2`` (:func:`~wavestack.pipeline.fit.run_moments.accumulate_runs`,
   :func:`~wavestack.pipeline.fit.run_moments.contract_rows`);
2. ``A^T (w - s)`` and ``sum(w - s)`` by the projection's moment map;
3. the centring of :class:`~wavestack.pipeline.fit.fitter.Fitter` (the shift moved to the
   samples' mean when a constant is in the basis' span), ``c = G^{-1} b``, the mean returned
   through the response to a constant, the residual ``|w - s'|^2 - c . b`` clamped at zero
   (:class:`~wavestack.pipeline.fit.normal_equations.NormalEquations`);
4. the M x M maps to the method's coefficients (and, for ``qr``, to circle coefficients).

Steps 2-4 are the same arithmetic as the general path, written out as loops: a second
implementation of a few lines of algebra, kept because of what it saves. A small frame arrives
cold (after other work has flushed the caches), and then each numpy or BLAS call on the general
path costs 25-80 us on first touch (measured right after a 75 MB matrix-vector product: the
moment map's product, two solve products, the coefficient map); at 512 x 512 with 36 modes those
calls and the Python between them were a third of the refit. The two paths agree to rounding
(coefficients ~1e-14 relative; the residual sum of squares to ~1e-12 of ``|w - s|^2``, the
identity's own cancellation), which the tests check on random apertures.

The solved (orthonormal) coefficients come back too, so a residual map asked for costs one
evaluation of the basis on top (:meth:`MomentProjection.residual
<wavestack.pipeline.fit.moment_projection.MomentProjection.residual>`). Frames with a non-finite
sample inside the aperture come back as None, and the fitter takes its general path, which
applies the NaN policy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from .moment_projection import MomentProjection
from .normal_equations import NormalEquations
from .projection import check_frame
from .run_fill import FASTMATH
from .run_moments import accumulate_runs, contract_rows


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def _shift(frame, probe):  # pragma: no cover - compiled
    """The mean of the finite samples at ``probe`` (S, 2); 0 if none is finite."""
    total = 0.0
    count = 0
    for k in range(probe.shape[0]):
        value = np.float64(frame[probe[k, 0], probe[k, 1]])
        if np.isfinite(value):
            total += value
            count += 1
    return total / count if count else 0.0


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def _dot(a, b):  # pragma: no cover - compiled
    """``a . b`` of two vectors, as a loop (numba's ``np.dot`` would call BLAS)."""
    total = 0.0
    for i in range(a.shape[0]):
        total += a[i] * b[i]
    return total


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def _refit(frame, probe, origins, runs, rows_t, cols_t, size, moment_map, column_sums, inverse, constant,
           transforms, n_samples, centred, out, solved):  # pragma: no cover - compiled
    """Fill ``solved`` (M,) with the orthonormal coefficients and ``out`` (T, M) with the mapped
    ones; return the residual sum of squares (NaN when a fitted sample is not finite)."""
    shift = _shift(frame, probe)
    sums = np.zeros((cols_t.shape[0], cols_t.shape[1], rows_t.shape[2]))
    squares = accumulate_runs(frame, shift, origins, runs, cols_t, sums)
    if not np.isfinite(squares):
        return np.nan
    moments = np.empty((origins.shape[0], size, size))
    contract_rows(rows_t, sums, moments)
    flat = moments.reshape(-1)
    m = column_sums.shape[0]
    summed = _dot(moment_map[m], flat)
    centre = shift + summed / n_samples if centred else 0.0
    step = centre - shift
    product = np.empty(m)
    for i in range(m):
        product[i] = _dot(moment_map[i], flat) - step * column_sums[i]
    squares = squares - 2.0 * step * summed + n_samples * step * step
    basis = np.empty(m)
    for i in range(m):
        basis[i] = _dot(inverse[i], product)
    fitted = _dot(basis, product)
    for i in range(m):
        basis[i] += centre * constant[i]
        solved[i] = basis[i]
    for t in range(transforms.shape[0]):
        for i in range(m):
            out[t, i] = _dot(transforms[t, i], basis)
    residual_sq = squares - fitted
    return residual_sq if residual_sq > 0.0 else 0.0


@dataclass(frozen=True, eq=False)
class RunFit:
    """What the one-call refit gives for one frame.

    Attributes
    ----------
    solved : ndarray, shape (M,)
        The orthonormal coefficients (what the projection's ``evaluate`` takes, for a residual map).
    mapped : ndarray, shape (T, M)
        ``solved`` through each of the fitter's maps (the method's coefficients, then the circle ones).
    residual_sq : float
        The residual sum of squares from the normal-equation identity.
    """

    solved: NDArray[np.float64]
    mapped: NDArray[np.float64]
    residual_sq: float


@dataclass(frozen=True, eq=False)
class RunRefit:
    """A fitter's refit of one frame in one compiled call (see the module docstring).

    Build it with :meth:`serving`; :meth:`fit` gives the solved and mapped coefficients and the
    residual sum of squares, as the fitter's general path would.

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline import build_fitter
    >>> rows, cols = np.mgrid[:64, :64]
    >>> fitter = build_fitter((rows - 31.5) ** 2 + (cols - 31.5) ** 2 < 30**2, modes=10, dtype=np.float64)
    >>> frame = np.nan_to_num(fitter.surface(np.eye(10)[4] * 0.1)) + 2.0
    >>> refit = RunRefit.serving(fitter._projection, fitter._equations, fitter._coefficient_transform[None])
    >>> mapped = refit.fit(frame).mapped
    >>> round(float(mapped[0, 4]), 9), bool(np.allclose(mapped[0], fitter.fit(frame).coefficients))
    (0.1, True)
    """

    shape: tuple[int, int]
    n_samples: int
    centred: bool
    size: int
    probe: NDArray[np.int64]
    origins: NDArray[np.int64]
    runs: NDArray[np.int64]
    rows_t: NDArray[np.float64]
    cols_t: NDArray[np.float64]
    moment_map: NDArray[np.float64]
    column_sums: NDArray[np.float64]
    inverse: NDArray[np.float64]
    constant: NDArray[np.float64]
    transforms: NDArray[np.float64]

    @classmethod
    def serving(cls, projection: MomentProjection, equations: NormalEquations,
                transforms: NDArray[np.float64]) -> RunRefit | None:
        """The one-call refit of a fitter, or None where it does not serve.

        Parameters
        ----------
        projection : MomentProjection
            Served when it has a run pass.
        equations : NormalEquations
            Served without physical-term removal.
        transforms : ndarray, shape (T, M, M)
            Maps from the solved (orthonormal) coefficients to those the fitter reports.
        """
        passes = projection.run_pass
        if passes is None or equations.has_removal:
            return None
        return cls(shape=projection.shape, n_samples=int(equations.n_samples),
                   centred=bool(equations.constant_in_span), size=passes.size, probe=projection.probe,
                   origins=passes.origins, runs=passes.runs, rows_t=passes.rows_t, cols_t=passes.cols_t,
                   moment_map=np.ascontiguousarray(projection.moment_map), column_sums=equations.column_sums,
                   inverse=np.ascontiguousarray(equations.basis_inverse),
                   constant=equations.constant_response.basis, transforms=np.ascontiguousarray(transforms))

    def fit(self, frame: NDArray) -> RunFit | None:
        """One frame's coefficients (solved and mapped) and residual sum of squares.

        Returns None when a sample inside the aperture is not finite (the caller's NaN policy
        decides). Raises :class:`~wavestack.pipeline.fit.results.InvalidFrame` for a frame of another
        shape or a dtype that is not real.
        """
        frame = check_frame(frame, self.shape)
        out = np.empty(self.transforms.shape[:2])
        solved = np.empty(self.transforms.shape[1])
        residual_sq = _refit(frame, self.probe, self.origins, self.runs, self.rows_t, self.cols_t, self.size,
                             self.moment_map, self.column_sums, self.inverse, self.constant, self.transforms,
                             float(self.n_samples), self.centred, out, solved)
        return RunFit(solved, out, residual_sq) if math.isfinite(residual_sq) else None
