"""Moments of a small frame up to degree 7 in one compiled walk over its fitted pixels.

The moment refit (:mod:`~wavestack.pipeline.fit.moment_projection`) needs, per strip, the moments
``M[j, k] = sum_{fitted (r, c)} P_j(v_r) (w[r, c] - s) P_k(u_c)`` for ``j, k <= D`` and the sum of
squares ``|w - s|^2``. For D <= 7 (36 Noll modes and fewer) on strips at most 512 columns wide,
this module computes them with one compiled call, without a buffer and without BLAS:

* one loop (numba) walks the runs of fitted pixels (:func:`~wavestack.pipeline.fit.run_fill.fitted_runs`)
  and keeps eight running sums per run, ``q_k = sum_c (w[r, c] - s) P_k(u_c)`` for k = 0..7 (zero
  table rows pad D < 7), plus the squares: nine float64 accumulators that the compiler
  vectorises along the run. The column table (8 rows x width x 8 B, 32 KB at 512) stays in the
  48 KB L1 cache; at 1024 columns it does not, and this pass ran 1.5-2x slower than the chunked
  matrix product (measured), hence the width limit;
* each run's sums are added into ``Q[k, r]``; at the end ``M = P_v^T Q^T``.

All strips go through one call (their runs and tables packed, :class:`RunPass`). The two steps
are compiled functions of their own (:func:`accumulate_runs`, :func:`contract_rows`) so that the
whole refit can call them too (:mod:`~wavestack.pipeline.fit.run_refit`).

Why a second pass beside the chunked product (:mod:`~wavestack.pipeline.fit.moment_chunks`): a
small frame's refit is dominated by touching memory and code, not by arithmetic. When the caches
are warm the two are equally fast (0.10-0.14 ms at 512 x 512, 36 modes), but a frame arrives
cold, after other work: then every library the refit enters (a BLAS kernel, numpy's error state,
the copy) costs 25-80 us on first touch (measured right after a 75 MB matrix-vector product), and
this pass enters one.

Precision: every product and sum is float64 (samples are converted as they are read), so a
float32 frame gets the float64 moments of its samples, ~1e-16 relative. The additions may be
reordered (``fastmath`` with ``reassoc`` and ``contract`` only); NaN and infinities keep their IEEE
meaning, so a non-finite fitted sample makes the sums non-finite, which is how the caller finds
it. Samples outside the runs are never read.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from .legendre_moments import Strip
from .run_fill import FASTMATH, fitted_runs

# Largest total degree this pass serves: its eight running sums are P_0 .. P_7.
RUN_PASS_MAX_DEGREE = 7
# Widest strip it serves, columns: 8 float64 table rows of this width fill 32 KB of a 48 KB L1.
RUN_PASS_MAX_WIDTH = 512


def run_pass_serves(degree: int, strips: list[Strip]) -> bool:
    """Whether :class:`RunPass` serves a basis of this total degree on these strips."""
    return degree <= RUN_PASS_MAX_DEGREE and all(s.col1 - s.col0 <= RUN_PASS_MAX_WIDTH for s in strips)


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def accumulate_runs(frame, shift, origins, runs, cols_t, sums):  # pragma: no cover - compiled
    """Add each run's eight column sums into ``sums[k, :, r]`` (S, 8, rows); return ``|w - s|^2``."""
    squares = 0.0
    for i in range(runs.shape[0]):
        k = runs[i, 0]
        r = runs[i, 1]
        a = runs[i, 2]
        b = runs[i, 3]
        source = frame[origins[k, 0] + r, origins[k, 1] + a:origins[k, 1] + b]
        table = cols_t[k]
        t0 = table[0, a:b]
        t1 = table[1, a:b]
        t2 = table[2, a:b]
        t3 = table[3, a:b]
        t4 = table[4, a:b]
        t5 = table[5, a:b]
        t6 = table[6, a:b]
        t7 = table[7, a:b]
        q0 = q1 = q2 = q3 = q4 = q5 = q6 = q7 = run_squares = 0.0
        for c in range(b - a):
            x = np.float64(source[c]) - shift
            run_squares += x * x
            q0 += x * t0[c]
            q1 += x * t1[c]
            q2 += x * t2[c]
            q3 += x * t3[c]
            q4 += x * t4[c]
            q5 += x * t5[c]
            q6 += x * t6[c]
            q7 += x * t7[c]
        squares += run_squares
        out = sums[k]
        out[0, r] += q0
        out[1, r] += q1
        out[2, r] += q2
        out[3, r] += q3
        out[4, r] += q4
        out[5, r] += q5
        out[6, r] += q6
        out[7, r] += q7
    return squares


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def contract_rows(rows_t, sums, moments):  # pragma: no cover - compiled
    """``moments[k, j, i] = sum_r P_j(v_r) sums[k, i, r]`` for j, i < moments.shape[1]."""
    size = moments.shape[1]
    for k in range(moments.shape[0]):
        for j in range(size):
            p = rows_t[k, j]
            for i in range(size):
                q = sums[k, i]
                total = 0.0
                for r in range(p.shape[0]):
                    total += p[r] * q[r]
                moments[k, j, i] = total


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def _run_moments(frame, shift, origins, runs, rows_t, cols_t, moments):  # pragma: no cover - compiled
    """Fill ``moments`` (S, D + 1, D + 1); return ``|w - s|^2``."""
    sums = np.zeros((cols_t.shape[0], cols_t.shape[1], rows_t.shape[2]))  # allocated here: no numpy call
    squares = accumulate_runs(frame, shift, origins, runs, cols_t, sums)
    contract_rows(rows_t, sums, moments)
    return squares


class RunPass:
    """The moments (S, D + 1, D + 1) of a frame's strips and its ``|w - s|^2`` (see :func:`run_pass_serves`).

    Every strip's runs and tables are packed into a few arrays, so that one compiled call serves
    the whole frame.

    Parameters
    ----------
    strips : list of Strip
    inside : list of ndarray of bool
        Each strip's fitted pixels in its box.
    row_tables, col_tables : list of ndarray, float64
        Each strip's Legendre tables (rows x (D + 1), columns x (D + 1)), D <= 7.

    Attributes
    ----------
    origins : ndarray of int64, shape (S, 2)
        Each strip's first row and column in the frame.
    runs : ndarray of int64, shape (R, 4)
        ``strip, row, first column, column after the last`` of each run, rows and columns counted
        in the strip's box.
    rows_t, cols_t : ndarray of float64, shapes (S, 8, rows) and (S, 8, columns)
        ``P_j`` at each strip's rows and columns; zero rows above D, zero padding past a strip's size.

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline.fit.legendre_moments import Strip, legendre_table
    >>> strip = Strip(0, 4, 0, 5)
    >>> inside = np.ones((4, 5), dtype=bool)
    >>> rows, cols = legendre_table(0, 4, 2), legendre_table(0, 5, 2)
    >>> moments, squares = RunPass([strip], [inside], [rows], [cols]).moments(np.ones((4, 5)), 0.0)
    >>> float(moments[0, 0, 0]), squares
    (20.0, 20.0)
    """

    def __init__(self, strips: list[Strip], inside: list[NDArray[np.bool_]], row_tables: list[NDArray[np.float64]],
                 col_tables: list[NDArray[np.float64]]) -> None:
        size = col_tables[0].shape[1]
        if size > RUN_PASS_MAX_DEGREE + 1:
            raise ValueError(f"col_tables: expected at most {RUN_PASS_MAX_DEGREE + 1} columns (degree <= "
                             f"{RUN_PASS_MAX_DEGREE}), got {size}")
        self.size = size
        self.origins = np.array([(s.row0, s.col0) for s in strips], dtype=np.int64).reshape(-1, 2)
        self.runs = np.concatenate([np.column_stack((np.full(len(r), k), r)) for k, r in
                                    enumerate(fitted_runs(i) for i in inside)]).astype(np.int64)
        self.rows_t = _packed(row_tables)
        self.cols_t = _packed(col_tables)

    @property
    def nbytes(self) -> int:
        """Bytes of the runs and tables read per frame."""
        return int(self.runs.nbytes + self.rows_t.nbytes + self.cols_t.nbytes)

    def moments(self, frame: NDArray, shift: float) -> tuple[NDArray[np.float64], float]:
        """Moments (S, D + 1, D + 1) of ``frame - shift`` on the fitted pixels, and ``|frame - shift|^2``.

        Non-finite results mean a non-finite sample inside the aperture (float64 sums of finite
        float32 samples do not overflow).
        """
        moments = np.empty((self.origins.shape[0], self.size, self.size))
        squares = _run_moments(frame, float(shift), self.origins, self.runs, self.rows_t, self.cols_t, moments)
        return moments, squares


def _packed(tables: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Tables (n_k x (D + 1)) as one array (S, 8, max n_k): transposed, zero-padded."""
    packed = np.zeros((len(tables), RUN_PASS_MAX_DEGREE + 1, max(t.shape[0] for t in tables)))
    for k, table in enumerate(tables):
        packed[k, :table.shape[1], :table.shape[0]] = table.T
    return packed
