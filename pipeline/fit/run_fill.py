"""Copy the fitted pixels of a frame into a block, zeros elsewhere, in one compiled pass.

The moment refit multiplies a block of the frame, zero outside the aperture, by a table of
Legendre polynomials (:mod:`~wavestack.pipeline.fit.moment_chunks`). Making that block in numpy
takes three passes: a copy less the shift, a store of zeros through the outside pixels' indices
(a scatter, ~2 ns per index: at 512 x 512 half of the refit) and a sum of squares. Here the
aperture is kept as *runs*, the stretches of fitted pixels along each row of the block, and one
compiled loop (numba) walks them in memory order: it writes zeros over the gap before a run,
copies the run less the shift and adds its squares. Samples outside the runs are never read, so
NaN or infinite values there cannot reach the sums.

The squares are accumulated in float64 whatever the block's dtype (each value is formed in the
block's dtype first, so that the sum is the exact |w - s|^2 of the block the product reads).
Inside the loop the additions may be reordered (``reassoc``), which lets the compiler vectorise
them; NaN and infinities keep their IEEE meaning (no ``nnan``/``ninf``), so a non-finite sample in
a run makes the sum non-finite, which is how the caller finds it.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

# The compiled loops of the fit (here, run_moments, run_refit) allow reassociation and contraction
# only: the sums may be reordered and fused, NaN stays NaN.
FASTMATH = {"reassoc", "contract"}


def fitted_runs(inside: NDArray[np.bool_]) -> NDArray[np.int64]:
    """The runs of fitted pixels of a block, row by row, left to right.

    Parameters
    ----------
    inside : ndarray of bool, shape (rows, cols)

    Returns
    -------
    ndarray of int64, shape (R, 3)
        ``row, first column, column after the last`` of each run, in memory (row-major) order.

    Examples
    --------
    >>> import numpy as np
    >>> fitted_runs(np.array([[0, 1, 1, 0, 1], [0, 0, 0, 0, 0], [1, 1, 0, 0, 0]], dtype=bool)).tolist()
    [[0, 1, 3], [0, 4, 5], [2, 0, 2]]
    """
    inside = np.asarray(inside, dtype=bool)
    padded = np.zeros((inside.shape[0], inside.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = inside
    steps = np.diff(padded, axis=1)
    rows, starts = np.nonzero(steps == 1)
    _, stops = np.nonzero(steps == -1)  # one stop per start, in the same row-major order
    return np.column_stack((rows, starts, stops)).astype(np.int64)


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH)
def fill_runs(frame, shift, row0, col0, runs, block):  # pragma: no cover - compiled; tested through its callers
    """``block <- frame - shift`` on the runs, 0 elsewhere; returns ``|block|^2`` in float64.

    Parameters
    ----------
    frame : ndarray, shape (rows, cols)
        The frame (any float dtype, any strides).
    shift : float
        Subtracted from every fitted sample, in the block's dtype.
    row0, col0 : int
        The frame's row and column of the block's first pixel.
    runs : ndarray of int64, shape (R, 3)
        :func:`fitted_runs` of the block.
    block : ndarray, shape (h, w), C-contiguous
        Written whole.

    Examples
    --------
    >>> import numpy as np
    >>> frame = np.array([[np.nan, 2.0, 3.0], [4.0, np.nan, 6.0]])
    >>> inside = np.isfinite(frame)
    >>> block = np.empty((2, 3))
    >>> fill_runs(frame, 1.0, 0, 0, fitted_runs(inside), block), block.tolist()
    (39.0, [[0.0, 1.0, 2.0], [3.0, 0.0, 5.0]])
    """
    width = block.shape[1]
    flat = block.reshape(-1)
    done = 0
    squares = 0.0
    for i in range(runs.shape[0]):
        start = runs[i, 0] * width + runs[i, 1]
        length = runs[i, 2] - runs[i, 1]
        gap = flat[done:start]
        for k in range(gap.shape[0]):
            gap[k] = 0
        source = frame[row0 + runs[i, 0], col0 + runs[i, 1]:col0 + runs[i, 2]]
        target = flat[start:start + length]
        run_squares = 0.0
        for k in range(length):
            value = source[k] - shift
            target[k] = value
            run_squares += np.float64(target[k]) * np.float64(target[k])
        squares += run_squares
        done = start + length
    tail = flat[done:]
    for k in range(tail.shape[0]):
        tail[k] = 0
    return squares
