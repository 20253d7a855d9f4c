"""One pass over the frame for the moment refit, in cache-sized chunks: float32 or float64 sums.

The moment refit (:mod:`wavestack.pipeline.fit.moment_projection`) needs, per strip of fitted
pixels, the moments ``P_v^T (W - s) P_u`` of the frame less a shift and ``|W - s|^2``. Each chunk of
rows of a strip is cut to the columns its fitted pixels span, and per frame

1. copied into a buffer of the pass's dtype less the shift, with zeros outside the fitted pixels,
   by one compiled walk over the block's runs of fitted pixels
   (:func:`~wavestack.pipeline.fit.run_fill.fill_runs`; a float32 frame read into float64 is
   converted in the same step; the buffer stays in L2). Samples outside the runs are never read,
   so NaN or infinite values there do not matter. The same walk adds ``|w - s|^2`` in float64;
2. multiplied by the chunk's rows of the column Legendre table (BLAS gemm: ``W P_u``, D + 1 wide).

The row products ``P_v^T (W P_u)`` are then taken in float64, so sums in the pass's dtype run only
along one row of a chunk (at most a few thousand terms of the centred frame). A non-finite result
(a NaN or an infinity inside the aperture, or overflow) sends the frame back to
:class:`~wavestack.pipeline.fit.moment_projection.MomentProjection`, which applies the NaN policy
and sums the finite fitted samples in a float64 pass of their own.

Precision of the float32 pass (float32 frames only). The squares are summed in float64 from the
float32 block (so the residual identity ``|w|^2 - c.b`` is not limited by them); the products are
not: summing in float32 leaves each row sum ~1e-7 of the row's |w - s| off; the map to the coefficients amplifies that as in
:mod:`~wavestack.pipeline.fit.legendre_moments`. Measured against the float64 refit of the same
float32 samples (centred disk of radius 0.4375 x size, random unit-RMS Zernike wavefronts of 0.02
per mode plus 1e-3 noise, no offset; norm-wise relative error of the coefficients):

======  ===========  ======================  ==============================
degree  amplif.      1024 x 1024             2048 x 2048 (256 x 256)
======  ===========  ======================  ==============================
2       5            5e-9                    -
4       31           5e-9                    -
6       194          -                       2.3e-8
7       380          5.1e-8                  1.0e-7 (7.8e-8)
8       1160         1.0e-6                  9.0e-7 (3.9e-7)
9       2210         2.1e-6                  -
10      6880         1.7e-6                  (2.0e-6)
======  ===========  ======================  ==============================

so the float32 pass serves degrees up to :data:`FLOAT32_MAX_DEGREE` (7: 36 Noll modes) where the
stored columns' amplification is at most :data:`FLOAT32_MAX_AMPLIFICATION`, keeping the error
~20x inside :data:`FLOAT32_TOLERANCE` (1e-6); the float32 operator refit of the same frames errs
by 5e-6 at degree 7. Higher degrees, and float64 frames, use the float64 pass (the 1e-9 bound of
:mod:`~wavestack.pipeline.fit.legendre_moments`). The bound is on the orthonormal coefficients; an
ill-conditioned basis' own coefficients add its noise gain, as they do to the frame's own rounding.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .legendre_moments import Strip
from .run_fill import fill_runs, fitted_runs

# Norm-wise relative error of the coefficients the float32 pass is allowed, against the float64
# refit of the same samples: the order of the float32 operator refit's (5e-6 at degree 7).
FLOAT32_TOLERANCE = 1e-6
# Largest total degree served in float32, and the largest amplification of the stored columns'
# coefficients (:func:`~wavestack.pipeline.fit.legendre_moments.amplification`): measured, the
# error is ~1e-9 x amplification (disks: 380 at degree 7, 1160 at degree 8).
FLOAT32_MAX_DEGREE = 7
FLOAT32_MAX_AMPLIFICATION = 1000.0
# Bytes of one chunk's buffer: it and its source rows stay in a 2-4 MB L2 cache (measured best of
# 128 KB to 1 MB at 1024 x 1024, 36 modes).
_CHUNK_BYTES = 256 * 1024


@dataclass(frozen=True)
class Chunk:
    """Rows ``[row0, row1)`` and columns ``[col0, col1)`` of a strip, read as one block.

    Attributes
    ----------
    runs : ndarray of int64, shape (R, 3)
        The block's runs of fitted pixels (:func:`~wavestack.pipeline.fit.run_fill.fitted_runs`,
        in block coordinates): the only samples read.
    """

    row0: int
    row1: int
    col0: int
    col1: int
    runs: NDArray[np.int64]


def plan_chunks(inside: NDArray[np.bool_], strip: Strip, chunk_bytes: int = _CHUNK_BYTES,
                itemsize: int = 4) -> list[Chunk]:
    """The chunks of one strip: each a block of rows cut to the columns its fitted pixels span.

    Parameters
    ----------
    inside : ndarray of bool, shape (strip rows, strip columns)
        The fitted pixels of the strip's box.
    strip : Strip
    chunk_bytes, itemsize : int
        Bytes of a chunk's buffer and of one of its values (they set its height).

    Returns
    -------
    list of Chunk
        Frame coordinates; chunks without a fitted pixel are left out.
    """
    height = max(1, chunk_bytes // (itemsize * inside.shape[1]))
    chunks = []
    for top in range(0, inside.shape[0], height):
        block = inside[top:top + height]
        used = np.flatnonzero(block.any(axis=0))
        if used.size == 0:
            continue
        left, right = int(used[0]), int(used[-1]) + 1
        chunks.append(Chunk(strip.row0 + top, strip.row0 + top + block.shape[0], strip.col0 + left,
                            strip.col0 + right, fitted_runs(block[:, left:right])))
    return chunks


class ChunkedPass:
    """The moments ``P_v^T (W - s) P_u`` of a frame in one pass, row sums in ``dtype``.

    Parameters
    ----------
    strips : list of Strip
    inside : list of ndarray of bool
        Each strip's fitted pixels in its box.
    row_tables, col_tables : list of ndarray, float64
        Each strip's Legendre tables (rows x (D + 1), columns x (D + 1)).
    dtype : numpy dtype
        float32 (float32 frames, low degrees: see the module docstring) or float64.

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline.fit.legendre_moments import Strip, legendre_table
    >>> strip = Strip(0, 4, 0, 5)
    >>> inside = np.ones((4, 5), dtype=bool)
    >>> rows, cols = legendre_table(0, 4, 2), legendre_table(0, 5, 2)
    >>> moments, squares = ChunkedPass([strip], [inside], [rows], [cols], np.float32).moments(
    ...     np.ones((4, 5), dtype=np.float32), 0.0)
    >>> float(moments[0, 0, 0]), squares
    (20.0, 20.0)
    """

    def __init__(self, strips: list[Strip], inside: list[NDArray[np.bool_]], row_tables: list[NDArray[np.float64]],
                 col_tables: list[NDArray[np.float64]], dtype: type = np.float32) -> None:
        self.dtype = np.dtype(dtype)
        self._strips = strips
        self._rows = row_tables
        # Column-major tables: gemm with a (width, D + 1) right factor ran 5-10% faster (measured).
        self._cols = [np.asfortranarray(t, dtype=self.dtype) for t in col_tables]
        self._chunks = [plan_chunks(i, s, _CHUNK_BYTES, self.dtype.itemsize) for i, s in zip(inside, strips)]
        self._largest = max((c.row1 - c.row0) * (c.col1 - c.col0) for chunks in self._chunks for c in chunks)
        # One buffer per thread, kept between frames: a fresh 256 KB array would be mapped (and
        # page-faulted) anew each frame, and threads sharing one fitter must not share a buffer.
        self._buffers = threading.local()

    @property
    def nbytes(self) -> int:
        """Bytes of the runs and column tables read per frame."""
        runs = sum(c.runs.nbytes for chunks in self._chunks for c in chunks)
        return int(runs + sum(t.nbytes for t in self._cols))

    def moments(self, frame: NDArray, shift: float) -> tuple[NDArray[np.float64], float]:
        """Moments (S, D + 1, D + 1) of ``frame - shift`` on the fitted pixels, and ``|frame - shift|^2``.

        ``shift`` is taken in the pass's dtype (the caller uses the same rounded value). Non-finite
        results mean a non-finite sample inside the aperture, or overflow.
        """
        shift = self.dtype.type(shift)
        size = self._cols[0].shape[1]
        moments = np.empty((len(self._strips), size, size))
        squares = 0.0
        work = getattr(self._buffers, "work", None)
        if work is None:
            work = self._buffers.work = np.empty(self._largest, dtype=self.dtype)
        for k, (strip, rows, cols, chunks) in enumerate(zip(self._strips, self._rows, self._cols, self._chunks)):
            partial = np.zeros((strip.row1 - strip.row0, size), dtype=self.dtype)
            for chunk in chunks:
                height, width = chunk.row1 - chunk.row0, chunk.col1 - chunk.col0
                block = work[: height * width].reshape(height, width)
                squares += fill_runs(frame, shift, chunk.row0, chunk.col0, chunk.runs, block)
                np.matmul(block, cols[chunk.col0 - strip.col0:chunk.col1 - strip.col0],
                          out=partial[chunk.row0 - strip.row0:chunk.row1 - strip.row0])
            moments[k] = rows.T @ partial.astype(np.float64)
        return moments, squares
