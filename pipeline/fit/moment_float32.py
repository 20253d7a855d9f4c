"""The float32 pass of the moment refit: float32 frames read once, in cache-sized chunks.

For a float32 frame the moment refit (:mod:`wavestack.pipeline.fit.moment_projection`) can skip
the conversion to float64, which alone costs about two reads of the frame. Each chunk of rows of a
strip is cut to the columns its fitted pixels span, and per frame

1. copied into a float32 buffer less the shift (one read of those pixels; the buffer stays in L2);
2. zeroed outside the fitted pixels by one store through precomputed indices (a disk: the
   corners of each chunk's box). Unlike a product with a 0/1 mask, this also clears NaN or
   infinite values outside the aperture;
3. squared into ``|w - s|^2``: a float32 sum per row (BLAS sdot), the rows added in float64 (one
   float32 sum per chunk would round the total to ~1e-7, which the residual identity
   ``|w|^2 - c.b`` turns into ~1e-3 of a small residual RMS);
4. multiplied by the chunk's rows of the column Legendre table (BLAS sgemm: ``W P_u``, D + 1 wide).

The row products ``P_v^T (W P_u)`` are then taken in float64, so float32 sums run only along one
row of a chunk (at most a few thousand terms of the centred frame). A non-finite sum (a NaN or an
infinity inside the aperture, or float32 overflow) sends the frame back to the float64 pass, which
applies the NaN policy.

Precision. Summing in float32 leaves each row sum ~1e-7 of the row's |w - s| off; the map to the
coefficients amplifies that as in :mod:`~wavestack.pipeline.fit.legendre_moments`. Measured
against the float64 operator refit of the same float32 samples (noisy random wavefronts, 1024 x
1024 disk, one strip below degree 8; see ``docs/results.md``), the norm-wise relative error of the
coefficients is within :data:`FLOAT32_TOLERANCE` up to degree :data:`FLOAT32_MAX_DEGREE`, the
same order as today's float32 operator refit; higher degrees keep the float64 pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .legendre_moments import Strip

# Norm-wise relative error of the coefficients the float32 pass is allowed, against the float64
# operator refit of the same samples: the order of a float32 sample's own rounding (6e-8) summed
# over a frame, and of the float32 operator refit's.
FLOAT32_TOLERANCE = 1e-6
# Largest total degree served in float32, and the largest amplification of the stored columns'
# coefficients (:func:`~wavestack.pipeline.fit.legendre_moments.amplification`): measured, the
# error is ~1e-9 x amplification (disks: 380 at degree 7, 1160 at degree 8).
FLOAT32_MAX_DEGREE = 7
FLOAT32_MAX_AMPLIFICATION = 1000.0
# Float32 bytes of one chunk: it and its source rows stay in a 2-4 MB L2 cache.
_CHUNK_BYTES = 256 * 1024


def _einsum_rows(a: NDArray[np.float32], b: NDArray[np.float32], out: NDArray[np.float32]) -> None:
    np.einsum("ij,ij->i", a, b, out=out)  # pragma: no cover - numpy 1.26 has no vecdot


# ``out[i] = a[i] . b[i]`` in float32: BLAS sdot per row (numpy >= 2), else einsum.
_row_dot = getattr(np, "vecdot", _einsum_rows)


@dataclass(frozen=True)
class Chunk:
    """Rows ``[row0, row1)`` and columns ``[col0, col1)`` of a strip, read as one block.

    Attributes
    ----------
    outside : ndarray of intp
        Flat (row-major) indices in the block of the pixels that are not fitted: set to zero
        after the copy (one fancy-index store, which also clears NaN or infinite values).
    """

    row0: int
    row1: int
    col0: int
    col1: int
    outside: NDArray[np.intp]


def plan_chunks(inside: NDArray[np.bool_], strip: Strip, chunk_bytes: int = _CHUNK_BYTES) -> list[Chunk]:
    """The chunks of one strip: each a block of rows cut to the columns its fitted pixels span.

    Parameters
    ----------
    inside : ndarray of bool, shape (strip rows, strip columns)
        The fitted pixels of the strip's box.
    strip : Strip
    chunk_bytes : int
        Float32 bytes of a chunk (sets its height).

    Returns
    -------
    list of Chunk
        Frame coordinates; chunks without a fitted pixel are left out.
    """
    height = max(1, chunk_bytes // (4 * inside.shape[1]))
    chunks = []
    for top in range(0, inside.shape[0], height):
        block = inside[top:top + height]
        used = np.flatnonzero(block.any(axis=0))
        if used.size == 0:
            continue
        left, right = int(used[0]), int(used[-1]) + 1
        chunks.append(Chunk(strip.row0 + top, strip.row0 + top + block.shape[0], strip.col0 + left,
                            strip.col0 + right, np.flatnonzero(~block[:, left:right])))
    return chunks


class Float32Pass:
    """The moments ``P_v^T (W - s) P_u`` of float32 frames, one pass, float32 row sums.

    Parameters
    ----------
    strips : list of Strip
    inside : list of ndarray of bool
        Each strip's fitted pixels in its box.
    row_tables, col_tables : list of ndarray, float64
        Each strip's Legendre tables (rows x (D + 1), columns x (D + 1)).

    Example
    -------
    >>> import numpy as np
    >>> from wavestack.pipeline.fit.legendre_moments import Strip, legendre_table
    >>> strip = Strip(0, 4, 0, 5)
    >>> inside = np.ones((4, 5), dtype=bool)
    >>> rows, cols = legendre_table(0, 4, 2), legendre_table(0, 5, 2)
    >>> moments, squares = Float32Pass([strip], [inside], [rows], [cols]).moments(
    ...     np.ones((4, 5), dtype=np.float32), np.float32(0.0))
    >>> float(moments[0, 0, 0]), squares
    (20.0, 20.0)
    """

    def __init__(self, strips: list[Strip], inside: list[NDArray[np.bool_]], row_tables: list[NDArray[np.float64]],
                 col_tables: list[NDArray[np.float64]]) -> None:
        self._strips = strips
        self._rows = row_tables
        self._cols = [np.ascontiguousarray(t, dtype=np.float32) for t in col_tables]
        self._chunks = [plan_chunks(i, s) for i, s in zip(inside, strips)]
        largest = max((c.row1 - c.row0) * (c.col1 - c.col0) for chunks in self._chunks for c in chunks)
        self._work = np.empty(largest, dtype=np.float32)

    @property
    def nbytes(self) -> int:
        """Bytes of the zeroing indices and float32 tables read per frame."""
        indices = sum(c.outside.nbytes for chunks in self._chunks for c in chunks)
        return int(indices + sum(t.nbytes for t in self._cols))

    def moments(self, frame: NDArray[np.float32], shift: np.float32) -> tuple[NDArray[np.float64], float]:
        """Moments (S, D + 1, D + 1) of ``frame - shift`` on the fitted pixels, and ``|frame - shift|^2``.

        Non-finite results mean a non-finite sample inside the aperture, or float32 overflow.
        """
        size = self._cols[0].shape[1]
        moments = np.empty((len(self._strips), size, size))
        squares = 0.0
        work = self._work
        for k, (strip, rows, cols, chunks) in enumerate(zip(self._strips, self._rows, self._cols, self._chunks)):
            partial = np.zeros((strip.row1 - strip.row0, size), dtype=np.float32)
            row_squares = np.zeros(strip.row1 - strip.row0, dtype=np.float32)
            for chunk in chunks:
                height, width = chunk.row1 - chunk.row0, chunk.col1 - chunk.col0
                block = work[: height * width].reshape(height, width)
                np.subtract(frame[chunk.row0:chunk.row1, chunk.col0:chunk.col1], shift, out=block)
                work[chunk.outside] = 0.0
                here = slice(chunk.row0 - strip.row0, chunk.row1 - strip.row0)
                _row_dot(block, block, out=row_squares[here])
                np.matmul(block, cols[chunk.col0 - strip.col0:chunk.col1 - strip.col0], out=partial[here])
            moments[k] = rows.T @ partial.astype(np.float64)
            squares += float(row_squares.sum(dtype=np.float64))
        return moments, squares
