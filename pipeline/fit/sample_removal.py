"""A fit refitted without some of its samples, by a rank-k downdate: no pass over the frame or the operator.

A fit keeps what its normal equations were made of (:class:`~.results.RefitState`): ``b = A_U^T (w_U - s)``,
``|w_U - s|^2``, ``sum(w_U - s)`` over the samples ``U`` it used, the samples it had already
dropped (their share of ``A^T A``), and its terms ``t`` (basis and removed physical terms, in the
stored orthonormal columns). Leaving out k more samples ``S`` (rows ``R = A_S``, values ``w_S``) is

* ``b' = b - R^T (w_S - s)``, ``|w' - s|^2`` and ``sum(w' - s)`` less the same k values, and the
  dropped share ``+ R^T R``, ``+ R^T 1``: the normal equations of ``K = U \\ S`` exactly, solved as
  any fit's are (:class:`~wavestack.pipeline.fit.normal_equations.NormalEquations`); so the new
  terms ``t'`` are the full refit's to rounding (float64: ~1e-15 waves on a 140,000-sample map);
* the new residual ``r' = w - A t' = r - A d`` on ``K`` (``d = t' - t``), whose figures come from
  the old residual map ``r`` without evaluating ``A d`` everywhere:

  - ``|r'_K|^2 = |r_K|^2 - 2 d . A_K^T r_K + d^T (A_K^T A_K) d``, with
    ``A_K^T r_K = (b + s A_U^T 1 - G_U t) - R^T r_S`` (the normal equations' own residual vector,
    which is not zero for the removed terms: they are removed first, then the basis fitted, as
    interferometer software does it). Unlike the identity ``|w'|^2 - c . b``, nothing here
    cancels: every term is of the size of the residual or smaller;
  - the peak-to-valley exactly: with ``V`` the eigenvectors of ``A^T A`` and ``m_j`` the largest
    ``|A_i v_j|`` over the samples (:class:`ChangeBound`, once per fitter),
    ``|(A d)_i| <= sum_j m_j |v_j . d|`` (the triangle inequality), so only samples whose old
    residual lies within twice that of the old extremes over ``K`` can hold the new ones; ``A d``
    is evaluated at those few. The eigenvectors keep the bound tight where the columns are
    nearly dependent (the mapped basis' piston and tilt against the removed physical ones): a
    large ``d`` along such a direction moves no sample much, and its ``m_j`` is small.

The residual map itself (``r - A d`` everywhere, one pass over the operator) is made only when
asked for. Reference: the rank-k downdate of normal equations (Golub & Van Loan, *Matrix
Computations*, 4th ed., section 6.5); the residual update is the same algebra as the fitter's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Protocol

import numba
import numpy as np
from numpy.typing import NDArray

from .normal_equations import NormalEquations
from .projection import Downdate, Projected, check_frame
from .results import FitResult, InvalidFrame, NanPolicy, RefitState

__all__ = ["ChangeBound", "SampledColumns", "refit_state", "refit_without"]


def refit_state(projected: Projected, terms: NDArray[np.float64]) -> RefitState:
    """The state a fit keeps: its projection's sums (no per-sample arrays) and its terms."""
    dropped = projected.downdate
    return RefitState(projected.product, projected.squares, projected.total, projected.shift,
                      None if dropped is None else dropped.gram, None if dropped is None else dropped.column_sums,
                      0 if dropped is None else dropped.count, terms)


def _projected_of(state: RefitState) -> Projected:
    dropped = None
    if state.dropped_gram is not None and state.dropped_sums is not None:
        dropped = Downdate(state.dropped_gram, state.dropped_sums, state.dropped_count)
    return Projected(state.product, state.squares, state.total, state.shift, dropped)


class SampledColumns(Protocol):
    """What the refit needs of a fitter's projection: its frame shape and columns, their rows and bound,
    their values for given terms, a frame's sums."""

    shape: tuple[int, int]
    n_columns: int

    def rows_at(self, pixels: NDArray[np.intp]) -> NDArray[np.float64]: ...

    @property
    def change_bound(self) -> ChangeBound: ...

    def evaluate(self, terms: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def project(self, frame: NDArray, nan_policy: NanPolicy) -> Projected: ...


def refit_without(frame: NDArray[np.floating], fit: FitResult, dropped: NDArray[np.bool_], residual: bool, *,
                  columns: SampledColumns, equations: NormalEquations,
                  solved_result: Callable[[NDArray, Projected], FitResult]) -> FitResult:
    """:meth:`Fitter.refit_without <wavestack.pipeline.fit.fitter.Fitter.refit_without>` (module notes), given
    the fitter's projection, its normal equations and how it makes a result (without its residual map)."""
    frame = check_frame(frame, columns.shape)
    pixels, dropped_residual = dropped_samples(fit, dropped)
    if pixels.size == 0:
        return fit
    state = fit.refit_state
    if state is None:  # a fit of the one-call refit keeps no sums: the projection gives them again
        state = solved_result(frame, columns.project(frame, "omit")).refit_state
        assert state is not None
    rows = columns.rows_at(pixels)
    projected = without_samples(_projected_of(state), rows, frame.reshape(-1)[pixels].astype(np.float64))
    assert projected.downdate is not None
    if equations.n_samples - projected.downdate.count <= columns.n_columns:
        raise InvalidFrame(f"dropped: leaving out {pixels.size} more samples leaves {fit.valid_count - pixels.size}; "
                           f"expected more than the {columns.n_columns} fitted terms")
    result = solved_result(frame, projected)
    assert result.refit_state is not None and fit.residual_map is not None
    change = result.refit_state.terms - state.terms
    residual_map = None
    if residual:
        residual_map = fit.residual_map - columns.evaluate(change)
        residual_map[dropped] = np.nan
        squares = float(np.nansum(np.square(residual_map)))
        peak_to_valley = float(np.nanmax(residual_map)) - float(np.nanmin(residual_map))
    else:
        squares, peak_to_valley = residual_figures(
            state=state, base=equations, fit=fit, rows=rows, dropped_residual=dropped_residual,
            change=change, bound=columns.change_bound, dropped=dropped, rows_at=columns.rows_at)
    return dataclasses.replace(result, residual_rms=math.sqrt(squares / result.valid_count), residual_pv=peak_to_valley,
                               residual_map=residual_map)


def dropped_samples(fit: FitResult, dropped: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Flat pixel indices of the samples to leave out, and the fit's residual there.

    Raises
    ------
    ValueError
        If ``fit`` has no residual map, ``dropped`` is not a boolean map of its shape, or a
        dropped pixel is not a sample the fit used (its residual is NaN there).
    """
    residual = fit.residual_map
    if residual is None:
        raise ValueError("fit: expected a fit made with residual=True (its residual map says which samples "
                         "it used), got one without a residual map")
    dropped = np.asarray(dropped)
    if dropped.dtype != np.bool_ or dropped.shape != residual.shape:
        raise ValueError(f"dropped: expected a boolean map of shape {residual.shape}, got "
                         f"{dropped.dtype} of shape {dropped.shape}")
    pixels = np.flatnonzero(dropped)
    at = residual.reshape(-1)[pixels]
    if not np.isfinite(at).all():
        raise ValueError(f"dropped: {int(np.count_nonzero(~np.isfinite(at)))} of the {pixels.size} pixels are "
                         "not samples the fit used; expected only samples it used")
    return pixels, at


def without_samples(projected: Projected, rows: NDArray[np.float64], values: NDArray[np.float64]) -> Projected:
    """The projection of the same frame with the samples of ``rows`` (k, K) and ``values`` (k,) left out."""
    centred = values - projected.shift
    before = projected.downdate
    share = Downdate(rows.T @ rows, rows.sum(axis=0), int(rows.shape[0]))
    if before is not None:
        share = Downdate(before.gram + share.gram, before.column_sums + share.column_sums, before.count + share.count)
    return Projected(projected.product - rows.T @ centred, projected.squares - float(centred @ centred),
                     projected.total - float(centred.sum()), projected.shift, share)


@dataclass(frozen=True, eq=False)
class ChangeBound:
    """A bound on how far a change of the terms moves any sample: ``|(A d)_i| <= m . |V^T d|`` (module notes).

    Attributes
    ----------
    directions : ndarray, shape (K, K)
        ``V``, the eigenvectors of ``A^T A`` (columns).
    reach : ndarray, shape (K,)
        ``m_j``, the largest ``|A_i v_j|`` over the samples.
    """

    directions: NDArray[np.float64]
    reach: NDArray[np.float64]

    @classmethod
    def of(cls, blocks: Callable[[], Iterator[NDArray[np.float64]]]) -> ChangeBound:
        """The bound of the operator whose rows ``blocks()`` yields, block by block (float64; read twice)."""
        gram = sum(block.T @ block for block in blocks())
        directions = np.linalg.eigh(gram)[1]
        reach = np.zeros(directions.shape[1])
        for block in blocks():
            np.maximum(reach, np.abs(block @ directions).max(axis=0), out=reach)
        return cls(directions, reach)

    def __call__(self, change: NDArray[np.float64]) -> float:
        """The largest ``|(A change)_i|`` can be over the samples."""
        return float(self.reach @ np.abs(self.directions.T @ change))


def residual_figures(*, state: RefitState, base: NormalEquations, fit: FitResult, rows: NDArray[np.float64],
                     dropped_residual: NDArray[np.float64], change: NDArray[np.float64], bound: ChangeBound,
                     dropped: NDArray[np.bool_], rows_at: Callable[[NDArray[np.intp]], NDArray[np.float64]]
                     ) -> tuple[float, float]:
    """Sum of squares and peak-to-valley of the new residual ``r - A change`` over the samples kept (module notes).

    ``rows_at(pixels)`` gives the operator rows (float64) of flat pixel indices; ``bound`` is the
    operator's :class:`ChangeBound`.
    """
    assert fit.residual_map is not None
    used_gram, used_sums = base.gram, base.column_sums
    if state.dropped_gram is not None and state.dropped_sums is not None:
        used_gram = used_gram - state.dropped_gram
        used_sums = used_sums - state.dropped_sums
    # A_U^T r_U from the normal equations of the fit, then the dropped samples taken out of it.
    normal_residual = state.product + state.shift * used_sums - used_gram @ state.terms
    kept_product = normal_residual - rows.T @ dropped_residual
    kept_gram = used_gram - rows.T @ rows
    squares = (fit.residual_rms ** 2 * fit.valid_count - float(dropped_residual @ dropped_residual)
               - 2.0 * float(change @ kept_product) + float(change @ kept_gram @ change))
    # Rounding of |A d| against its bound: relative 1e-6 and an absolute floor far below any residual.
    margin = 2.0 * bound(change) * (1.0 + 1e-6) + 1e-12
    candidates = _extreme_candidates(fit.residual_map, dropped, margin)
    moved = fit.residual_map.reshape(-1)[candidates] - rows_at(candidates) @ change
    return max(squares, 0.0), float(moved.max()) - float(moved.min())


@numba.njit(nogil=True, cache=True)
def _extreme_candidates(residual, dropped, margin):  # type: ignore[no-untyped-def]
    """Flat indices of the kept samples (finite residual, not dropped) within ``margin`` of the
    kept residual's maximum or minimum.

    One walk: a sample is held when it lies within ``margin`` of the extremes seen so far (which
    only widen, so every final candidate is held), then the held ones are sifted."""
    flat = residual.ravel()
    gone = dropped.ravel()
    held = np.empty(flat.size, dtype=np.intp)
    count = 0
    high, low = -np.inf, np.inf
    for i in range(flat.size):
        value = flat[i]
        if value == value and not gone[i]:
            if value > high:
                high = value
            if value < low:
                low = value
            if value >= high - margin or value <= low + margin:
                held[count] = i
                count += 1
    found = 0
    for k in range(count):
        value = flat[held[k]]
        if value >= high - margin or value <= low + margin:
            held[found] = held[k]
            found += 1
    return held[:found].copy()
