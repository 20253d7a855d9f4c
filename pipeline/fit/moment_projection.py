"""The refit of a polynomial basis by separable Legendre moments: one pass over the frame.

For each strip of the fitted pixels (:mod:`wavestack.pipeline.fit.legendre_moments`) the frame
is read once in row chunks that stay in cache (:mod:`wavestack.pipeline.fit.moment_chunks`): each
chunk is copied less a shift with zeros outside the fitted pixels and its ``|w|^2`` summed, in one
compiled walk over the fitted runs, then multiplied by the strip's column Legendre table; one more
(D + 1)-wide product per strip gives the moments, and one product with a fixed (K + 1) x S (D + 1)^2
matrix all of ``A^T w`` and ``sum(w)``. Nothing of size N x M exists. Small apertures up to
degree 7 take the run pass (:mod:`~wavestack.pipeline.fit.run_moments`, float64 sums); wider
float32 frames are summed in float32 products up to degree 7 (the moment_chunks docstring gives
the precision), everything else in float64. A frame whose sums come out non-finite (a NaN or
infinity inside the aperture, or overflow) has its bad samples found here and the NaN policy
applied; set to the shift, they add nothing to the float64 pass over the fitted samples, and a
downdate takes them out of the normal equations.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .legendre_moments import Strip, amplification, gram_of, legendre_table, strip_moments, triangle_index
from .moment_chunks import FLOAT32_MAX_AMPLIFICATION, FLOAT32_MAX_DEGREE, ChunkedPass
from .run_moments import RunPass, run_pass_serves
from .projection import Downdate, Projected, check_frame, check_frames, refuse_nonfinite
from .results import NanPolicy
from .sample_removal import ChangeBound

logger = logging.getLogger(__name__)

# Float64 bytes of the stacked chunk of a batched refit.
_BATCH_BYTES = 8 * 1024 * 1024
# Dropped samples above which their share of the Gram matrix comes from mask moments, not rows.
_ROWS_DOWNDATE_MAX = 2048


@dataclass(frozen=True)
class MomentState:
    """The stored form of a moment projection (what :mod:`~wavestack.pipeline.fit.store` saves).

    Attributes
    ----------
    mask : ndarray of bool, shape (rows, cols)
        The fitted pixels.
    strips : ndarray of int, shape (S, 4)
        ``row0, row1, col0, col1`` of each strip.
    degree : int
        D, the largest total degree of the columns.
    transform : ndarray, shape (K, S * L)
        Coefficients of the K columns in each strip's Legendre products (L = (D+1)(D+2)/2).
    """

    mask: NDArray[np.bool_]
    strips: NDArray[np.int64]
    degree: int
    transform: NDArray[np.float64]


class MomentProjection:
    """``A^T (w - s)`` from the moments of the frame, for columns that are polynomials.

    Parameters
    ----------
    state : MomentState
    """

    def __init__(self, state: MomentState) -> None:
        self.state = state
        self.shape = (int(state.mask.shape[0]), int(state.mask.shape[1]))
        self._strips = [Strip(*map(int, row)) for row in state.strips]
        self._degree = int(state.degree)
        self._index = triangle_index(self._degree)
        self._transform = state.transform
        self._width = self._index.size
        self._moment_map = _moment_map(state.transform, self._index, len(self._strips), self._degree + 1)
        self.n_columns = int(state.transform.shape[0])
        self._rows = [legendre_table(s.row0, s.row1, self._degree) for s in self._strips]
        self._cols = [legendre_table(s.col0, s.col1, self._degree) for s in self._strips]
        self._outside = [~state.mask[s.row0:s.row1, s.col0:s.col1] for s in self._strips]
        self.n_samples = int(sum(o.size - np.count_nonzero(o) for o in self._outside))
        self._probe = [divmod(_first_pixel(state.mask, s), self.shape[1]) for s in self._strips]
        inside = [~o for o in self._outside]
        self._double = ChunkedPass(self._strips, inside, self._rows, self._cols, np.float64)
        self._single = None  # float32 frames skip the float64 conversion where that stays exact enough
        self._runs = None  # small frames at low degree: one compiled call, any dtype
        amplified = max(amplification(self._strip_transform(k)) for k in range(len(self._strips)))
        if run_pass_serves(self._degree, self._strips):
            self._runs = RunPass(self._strips, inside, self._rows, self._cols)
        elif self._degree <= FLOAT32_MAX_DEGREE and amplified <= FLOAT32_MAX_AMPLIFICATION:
            self._single = ChunkedPass(self._strips, inside, self._rows, self._cols, np.float32)

    @property
    def float32_frame_pass(self) -> str:
        """The pass a float32 frame takes: ``"runs"`` (:mod:`~wavestack.pipeline.fit.run_moments`),
        ``"float32"`` or ``"float64"`` (chunked products, :mod:`~wavestack.pipeline.fit.moment_chunks`)."""
        if self._runs is not None:
            return "runs"
        return "float32" if self._single is not None else "float64"

    @property
    def run_pass(self) -> RunPass | None:
        """The compiled pass over the runs of fitted pixels, when it serves this basis (else None)."""
        return self._runs

    @property
    def probe(self) -> NDArray[np.int64]:
        """(row, column) of each strip's first fitted pixel, shape (S, 2): the shift's samples."""
        return np.array(self._probe, dtype=np.int64).reshape(-1, 2)

    @property
    def moment_map(self) -> NDArray[np.float64]:
        """The map (n_columns + 1, S (D + 1)^2) from the moments to ``A^T (w - s)`` and ``sum(w - s)``."""
        view = self._moment_map.view()
        view.flags.writeable = False
        return view

    @property
    def nbytes(self) -> int:
        """Bytes of the tables read once per frame besides the frame (float64 pass)."""
        return int(self._transform.nbytes + sum(r.nbytes for r in self._rows) + self._double.nbytes)

    def _strip_transform(self, k: int) -> NDArray[np.float64]:
        return self._transform[:, k * self._width:(k + 1) * self._width]

    def _shift(self, frame: NDArray) -> float:
        """The mean of each strip's first fitted sample (finite ones; 0 if none is)."""
        values = [float(frame[row, col]) for row, col in self._probe]  # no numpy call: a few samples
        finite = [v for v in values if math.isfinite(v)]
        return math.fsum(finite) / len(finite) if finite else 0.0

    def project(self, frame: NDArray, nan_policy: NanPolicy) -> Projected:
        """Moments of one frame (see :class:`~wavestack.pipeline.fit.projection.Projected`)."""
        frame = check_frame(frame, self.shape)
        shift = self._shift(frame)
        projected = self._first_pass(frame, shift)
        if projected is not None:
            return projected
        # Its sums are not finite: non-finite samples inside the aperture, or finite ones whose
        # float32 products (or float64 squares) overflow.
        bad = [~o & ~np.isfinite(frame[s.row0:s.row1, s.col0:s.col1]) for s, o in zip(self._strips, self._outside)]
        count = int(sum(np.count_nonzero(b) for b in bad))
        if count == 0:  # nothing to leave out: the float64 pass, whatever it sums to
            return self._summed(self._double, frame, shift, None)
        refuse_nonfinite(count, self.n_samples, self.n_columns, nan_policy)
        logger.debug("omitting %d non-finite samples by downdating the normal equations", count)
        downdate = self._downdate(bad, count)
        # The dropped samples set to the shift add nothing to the sums (their w - s is exactly 0), so
        # the float64 pass serves the frame as it is, and the downdate takes their rows out of the
        # equations: no pass of its own is made for the finite samples.
        filled = frame.astype(np.float64, copy=True)
        for strip, dropped in zip(self._strips, bad):
            filled[strip.row0:strip.row1, strip.col0:strip.col1][dropped] = shift
        if self._runs is not None:
            moments, squares = self._runs.moments(filled, shift)
            if math.isfinite(squares):
                return self._projected(moments, squares, shift, downdate)
        return self._summed(self._double, filled, shift, downdate)

    def _first_pass(self, frame: NDArray, shift: float) -> Projected | None:
        """The fast pass for this frame, or None when its sums are not finite (:meth:`project` decides)."""
        if self._runs is not None:
            moments, squares = self._runs.moments(frame, shift)
            # Finite float64 squares mean every fitted sample is finite and below ~1e154, so the
            # moments are finite too and nothing below can warn (no error-state switch needed).
            return self._projected(moments, squares, shift, None) if math.isfinite(squares) else None
        chunked = self._single if self._single is not None and frame.dtype == np.float32 else self._double
        return self._chunked(chunked, frame, shift)

    def _chunked(self, chunked: ChunkedPass, frame: NDArray, shift: float) -> Projected | None:
        """One chunked pass, or None when its sums are not finite (:meth:`project` decides)."""
        rounded = float(chunked.dtype.type(shift))
        with np.errstate(invalid="ignore", over="ignore"):
            moments, squares = chunked.moments(frame, rounded)
            sums = self._moment_map @ moments.reshape(-1)
        # A non-finite moment makes its row of sums non-finite (0 x inf is NaN); so may an
        # overflow of finite ones, which the float64 pass then sums again.
        if math.isfinite(squares) and math.isfinite(float(np.add.reduce(sums))):
            return Projected(sums[:-1], float(squares), float(sums[-1]), rounded, None)
        return None

    def _projected(self, moments: NDArray, squares: float, shift: float, downdate: Downdate | None) -> Projected:
        sums = self._moment_map @ moments.reshape(-1)
        return Projected(sums[:-1], float(squares), float(sums[-1]), shift, downdate)

    def _summed(self, chunked: ChunkedPass, frame: NDArray, shift: float, downdate: Downdate | None) -> Projected:
        """A float64 chunked pass, its sums kept even when they are not finite."""
        with np.errstate(invalid="ignore", over="ignore"):
            moments, squares = chunked.moments(frame, shift)
            return self._projected(moments, squares, shift, downdate)

    def project_many(self, frames: NDArray, keep_samples: bool = False) -> list[Projected | None]:
        """Moments of a stack of frames, one product per chunk of rows for the whole stack.

        Frames that the run pass serves, and float32 stacks that the float32 pass serves, go
        through it frame by frame (so that ``fit_many`` gives what ``fit`` gives; those passes are
        as fast per frame). Frames with a non-finite sample inside the aperture come back as None
        (the caller fits them one by one, with its NaN policy). ``keep_samples`` is accepted for the interface's
        sake: a moment residual reads the frame again.
        """
        frames = check_frames(frames, self.shape)
        if self._runs is not None or (self._single is not None and frames.dtype == np.float32):
            return [self._first_pass(frame, self._shift(frame)) for frame in frames]  # as fit() does
        with np.errstate(invalid="ignore", over="ignore"):  # frames with non-finite samples come back None
            return self._project_many(frames)

    def _project_many(self, frames: NDArray) -> list[Projected | None]:
        count = frames.shape[0]
        shifts = np.array([self._shift(frame) for frame in frames])
        size = self._degree + 1
        moments = np.empty((count, len(self._strips), size, size))
        squares = np.zeros(count)
        widest = max(s.col1 - s.col0 for s in self._strips)
        chunk = max(1, _BATCH_BYTES // (8 * widest * count))
        for k, (strip, rows, cols, out) in enumerate(zip(self._strips, self._rows, self._cols, self._outside)):
            width = strip.col1 - strip.col0
            partial = np.zeros((size, count * width))
            for start in range(strip.row0, strip.row1, chunk):
                stop = min(start + chunk, strip.row1)
                block = np.subtract(frames[:, start:stop, strip.col0:strip.col1], shifts[:, None, None],
                                    dtype=np.float64)
                np.copyto(block, 0.0, where=out[None, start - strip.row0:stop - strip.row0])
                squares += np.einsum("kij,kij->k", block, block)
                stacked = np.ascontiguousarray(block.transpose(1, 0, 2)).reshape(stop - start, -1)
                partial += rows[start - strip.row0:stop - strip.row0].T @ stacked
            per_frame = partial.reshape(size, count, width).transpose(1, 0, 2) @ cols  # (K, D+1, D+1)
            moments[:, k] = per_frame
        sums = moments.reshape(count, -1) @ self._moment_map.T  # (K frames, columns + 1): one product
        products, totals = sums[:, :-1], sums[:, -1]
        results: list[Projected | None] = []
        for i in range(count):
            finite = np.isfinite(squares[i]) and np.isfinite(products[i]).all()
            results.append(Projected(products[i], float(squares[i]), float(totals[i]), float(shifts[i]))
                           if finite else None)
        return results

    def _downdate(self, bad: list[NDArray[np.bool_]], count: int) -> Downdate:
        """The dropped samples' share of ``A^T A`` and ``A^T 1``: from their rows, or for many
        from the moments of their mask."""
        if count > _ROWS_DOWNDATE_MAX:
            mask = np.zeros(self.shape, dtype=bool)
            for strip, b in zip(self._strips, bad):
                mask[strip.row0:strip.row1, strip.col0:strip.col1] = b
            moments = strip_moments(mask, self._strips, self._degree)
            gram, sums = gram_of([self._strip_transform(k) for k in range(len(self._strips))], moments)
            return Downdate(gram, sums, count)
        pixels = np.concatenate([(rows + strip.row0) * self.shape[1] + cols + strip.col0
                                 for strip, (rows, cols) in zip(self._strips, map(np.nonzero, bad))])
        values = self.rows_at(pixels)
        return Downdate(values.T @ values, values.sum(axis=0), count)

    def rows_at(self, pixels: NDArray[np.intp]) -> NDArray[np.float64]:
        """The columns' values (float64, shape (k, K)) at flat pixel indices of fitted samples: one row each."""
        rows, cols = np.divmod(np.asarray(pixels, dtype=np.intp), self.shape[1])
        values = np.zeros((rows.size, self.n_columns))
        for k, (strip, outside) in enumerate(zip(self._strips, self._outside)):
            here = np.flatnonzero((rows >= strip.row0) & (rows < strip.row1) & (cols >= strip.col0) & (cols < strip.col1))
            r, c = rows[here] - strip.row0, cols[here] - strip.col0
            fitted = ~outside[r, c]
            here, r, c = here[fitted], r[fitted], c[fitted]
            if here.size == 0:
                continue
            products = (self._rows[k][r][:, :, None] * self._cols[k][c][:, None, :]).reshape(r.size, -1)
            values[here] = products[:, self._index] @ self._strip_transform(k).T
        return values

    @functools.cached_property
    def change_bound(self) -> ChangeBound:
        """How far a change of the terms can move a sample (computed once, on first use)."""
        pixels = np.flatnonzero(self.state.mask)
        step = 1 << 14
        return ChangeBound.of(lambda: (self.rows_at(pixels[i:i + step]) for i in range(0, pixels.size, step)))

    def evaluate(self, terms: NDArray[np.float64], mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """``A @ terms`` on the fitted pixels (or on ``mask``), NaN elsewhere; shape (rows, cols)."""
        size = self._degree + 1
        full = np.full(self.shape, np.nan)
        for k, (strip, rows, cols, out) in enumerate(zip(self._strips, self._rows, self._cols, self._outside)):
            square = np.zeros(size * size)
            square[self._index] = self._strip_transform(k).T @ terms
            values = rows @ square.reshape(size, size) @ cols.T
            keep = ~out if mask is None else mask[strip.row0:strip.row1, strip.col0:strip.col1]
            full[strip.row0:strip.row1, strip.col0:strip.col1][keep] = values[keep]
        return full

    def residual(self, frame: NDArray, projected: Projected | None, terms: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], float, float]:
        """The residual map ``w - A @ terms`` (NaN off the fitted or finite samples), its PV and its sum of squares.

        ``projected`` is not read (the map needs only the frame and the terms); it is taken so that
        both projections answer the same call, and the one-call refit passes None.
        """
        residual = self.evaluate(terms)  # NaN off the fitted pixels, which the subtraction keeps
        np.subtract(frame, residual, out=residual)
        residual[~np.isfinite(residual)] = np.nan
        peak_to_valley = float(np.nanmax(residual)) - float(np.nanmin(residual))
        return residual, peak_to_valley, float(np.nansum(np.square(residual)))


def _moment_map(transform: NDArray[np.float64], index: NDArray[np.intp], n_strips: int,
                size: int) -> NDArray[np.float64]:
    """The matrix taking the flat moments (S x size x size) to ``A^T (w - s)`` and, in its last
    row, ``sum(w - s)``: the transform spread over the (row, column) degree pairs it uses, zeros
    elsewhere, and a 1 at each strip's (0, 0) moment (``P_0 = 1``, so that moment is the plain sum).
    One product instead of a gather, a product and a sum per frame."""
    width = index.size
    spread = np.zeros((transform.shape[0] + 1, n_strips * size * size))
    for k in range(n_strips):
        spread[:-1, k * size * size + index] = transform[:, k * width:(k + 1) * width]
        spread[-1, k * size * size] = 1.0
    return spread


def _first_pixel(mask: NDArray[np.bool_], strip: Strip) -> int:
    """Flat index of the strip's first fitted pixel (its sample for the shift)."""
    box = mask[strip.row0:strip.row1, strip.col0:strip.col1]
    row, col = np.unravel_index(int(np.argmax(box)), box.shape)
    return (strip.row0 + int(row)) * mask.shape[1] + strip.col0 + int(col)
