"""The refit through a stored operator: gather the samples, one product with ``A`` (N x (M + k)).

Used for the mapped bases (``csf-qcm``, ``conformal``), which are not polynomials in the pixel
coordinates, and wherever the moment path is not chosen (``refit="operator"``, or an aperture on
which the moments would lose precision). The samples are centred on their mean before the product,
which keeps float32 sums accurate.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
from numpy.typing import NDArray

from .projection import Downdate, Projected, check_frame, check_frames, refuse_nonfinite
from .results import NanPolicy
from .sample_removal import ChangeBound

logger = logging.getLogger(__name__)

# Bytes of gathered samples of a batched refit handled by one product.
_BATCH_BYTES = 64 * 1024 * 1024


class OperatorProjection:
    """``A^T (w - mean)`` from the gathered samples and a stored operator.

    Parameters
    ----------
    shape : (int, int)
        Frame shape.
    flat_index : ndarray of intp, shape (N,)
        Row-major indices of the fitted samples.
    operator : ndarray, shape (N, K)
        The columns on the samples, in the fit dtype and its storage order.
    """

    def __init__(self, shape: tuple[int, int], flat_index: NDArray[np.intp], operator: NDArray[np.floating]) -> None:
        self.shape = (int(shape[0]), int(shape[1]))
        self.flat_index = flat_index
        self.operator = operator
        self.n_samples = int(flat_index.size)
        self.n_columns = int(operator.shape[1])

    @property
    def nbytes(self) -> int:
        """Bytes of the operator read once per frame."""
        return int(self.operator.nbytes)

    def _gather(self, frame: NDArray) -> NDArray[np.floating]:
        samples = np.take(frame.reshape(-1), self.flat_index)
        return samples.astype(self.operator.dtype, copy=False)

    def project(self, frame: NDArray, nan_policy: NanPolicy) -> Projected:
        """Gather, centre on the mean of the finite samples, one product with the operator."""
        samples = self._gather(check_frame(frame, self.shape))
        bad, downdate = None, None
        mean = float(samples.mean())
        if not np.isfinite(mean):
            bad = np.flatnonzero(~np.isfinite(samples))
            refuse_nonfinite(bad.size, self.n_samples, self.n_columns, nan_policy)
            logger.debug("omitting %d non-finite samples by downdating the normal equations", bad.size)
            rows = self.operator[bad].astype(np.float64)
            downdate = Downdate(rows.T @ rows, rows.sum(axis=0), int(bad.size))
            samples[bad] = 0.0
            mean = float(samples.sum()) / (self.n_samples - bad.size)
            samples[bad] = mean  # zero once centred: the dropped samples add nothing below
        samples -= samples.dtype.type(mean)
        product = (samples @ self.operator).astype(np.float64)
        return Projected(product, float(np.dot(samples, samples)), 0.0, mean, downdate, samples, bad)

    def project_many(self, frames: NDArray, keep_samples: bool = False) -> list[Projected | None]:
        """The same for a stack: one (frames x N) by (N x K) product per block of frames.

        Frames with a non-finite sample come back as None (fitted one by one by the caller).
        ``keep_samples`` keeps each frame's centred samples (for its residual).
        """
        frames = check_frames(frames, self.shape)
        per_block = max(1, _BATCH_BYTES // max(1, self.n_samples * self.operator.itemsize))
        results: list[Projected | None] = []
        for start in range(0, frames.shape[0], per_block):
            block = frames[start:start + per_block].reshape(-1, self.shape[0] * self.shape[1])
            samples = np.take(block, self.flat_index, axis=1).astype(self.operator.dtype, copy=False)
            means = samples.mean(axis=1)
            samples -= means[:, None].astype(samples.dtype)
            products = (samples @ self.operator).astype(np.float64)
            squares = np.einsum("ij,ij->i", samples, samples)
            for i, mean in enumerate(means):
                finite = np.isfinite(mean)
                kept = samples[i].copy() if keep_samples else None
                results.append(Projected(products[i], float(squares[i]), 0.0, float(mean), None, kept, None)
                               if finite else None)
        return results

    def rows_at(self, pixels: NDArray[np.intp]) -> NDArray[np.float64]:
        """The operator's rows (float64, shape (k, K)) at flat pixel indices of fitted samples."""
        return self.operator[np.searchsorted(self.flat_index, pixels)].astype(np.float64)

    @functools.cached_property
    def change_bound(self) -> ChangeBound:
        """How far a change of the terms can move a sample (computed once, on first use)."""
        step = 1 << 14
        return ChangeBound.of(lambda: (self.operator[i:i + step].astype(np.float64)
                                       for i in range(0, self.n_samples, step)))

    def evaluate(self, terms: NDArray[np.float64]) -> NDArray[np.float64]:
        """``A @ terms`` on the fitted samples, NaN elsewhere; shape (rows, cols)."""
        return self._scatter(self.operator[:, : terms.size] @ terms)

    def residual(self, frame: NDArray, projected: Projected, terms: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], float, float]:
        """The residual map (NaN off the fitted or finite samples), its peak-to-valley and its sum of squares."""
        # The terms in the operator's own type: a float64 vector against a float32 operator would
        # make numpy copy the whole operator to float64 on every call (7x the cost of the pass).
        # The residual is then as exact as the operator (float32: ~1e-7 relative to the map).
        centred = projected.centred
        assert centred is not None
        centred_residual = centred - self.operator @ terms.astype(self.operator.dtype)
        residual = centred_residual.astype(np.float64)
        residual += projected.shift
        if projected.bad is not None:  # dropped samples: NaN in the map, nothing in the sums
            residual[projected.bad] = 0.0
            squares = float(np.dot(residual, residual))
            residual[projected.bad] = np.nan
            peak_to_valley = float(np.nanmax(residual)) - float(np.nanmin(residual))
        else:
            squares = float(np.dot(residual, residual))
            peak_to_valley = float(residual.max()) - float(residual.min())
        return self._scatter(residual), peak_to_valley, squares

    def _scatter(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        full = np.full(self.shape, np.nan)
        full.reshape(-1)[self.flat_index] = values
        return full
