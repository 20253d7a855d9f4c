"""What a refit needs from the frame: ``b = A^T (w - s)`` and ``|w - s|^2`` over the fitted samples.

Two implementations share one small interface, so :class:`~wavestack.pipeline.fit.fitter.Fitter`
does not care how the product is made:

* :class:`~wavestack.pipeline.fit.operator_projection.OperatorProjection`: the stored operator
  ``A`` (N x (M + k)), gathered samples, one product (every basis, the mapped ones included);
* :class:`~wavestack.pipeline.fit.moment_projection.MomentProjection`: separable Legendre moments
  of the frame and a small fixed matrix (polynomial bases only; no N-sized array).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .results import InvalidFrame, NanPolicy


@dataclass(frozen=True)
class Downdate:
    """Samples dropped from one frame's fit (non-finite): their share of the normal equations.

    Attributes
    ----------
    gram : ndarray, shape (K, K)
        ``A_bad^T A_bad``.
    column_sums : ndarray, shape (K,)
        ``A_bad^T 1``.
    count : int
        Samples dropped.
    """

    gram: NDArray[np.float64]
    column_sums: NDArray[np.float64]
    count: int


@dataclass(frozen=True, eq=False)
class Projected:
    """One frame seen through the operator: everything the normal equations need.

    Attributes
    ----------
    product : ndarray, shape (K,)
        ``A^T (w - shift)`` over the finite fitted samples, float64.
    squares : float
        ``|w - shift|^2`` over the same samples.
    total : float
        ``sum(w - shift)`` over the same samples.
    shift : float
        The constant taken off every sample before the sums (keeps them accurate).
    downdate : Downdate or None
        The non-finite samples left out, or None when there were none.
    centred : ndarray or None
        The gathered samples less ``shift`` (operator path only; its residual reuses them).
    bad : ndarray or None
        Positions of the dropped samples in ``centred`` (operator path only).
    """

    product: NDArray[np.float64]
    squares: float
    total: float
    shift: float
    downdate: Downdate | None = None
    centred: NDArray[np.floating] | None = None
    bad: NDArray[np.intp] | None = None


def check_frame(frame: NDArray, shape: tuple[int, int]) -> NDArray:
    """The frame as an array of the aperture's shape and a real dtype, or InvalidFrame."""
    if type(frame) is not np.ndarray:
        frame = np.asarray(frame)
    if frame.shape != shape:
        raise InvalidFrame(f"frame: expected shape {shape} like the fitter's aperture, got {frame.shape}")
    if frame.dtype.kind not in "fiu":  # floating, signed or unsigned integer (not bool, not complex)
        raise InvalidFrame(f"frame: expected a real-valued array, got dtype {frame.dtype}")
    return frame


def check_frames(frames: NDArray, shape: tuple[int, int]) -> NDArray:
    """A stack of frames, shape (K, rows, cols), or InvalidFrame."""
    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.shape[1:] != shape:
        raise InvalidFrame(f"frames: expected shape (K, {shape[0]}, {shape[1]}) like the fitter's aperture, "
                           f"got {frames.shape}")
    return frames


def refuse_nonfinite(bad: int, total: int, columns: int, nan_policy: NanPolicy) -> None:
    """Raise :class:`InvalidFrame` when ``bad`` non-finite samples may not or cannot be left out."""
    if nan_policy not in ("raise", "omit"):
        raise ValueError(f"nan_policy: expected 'raise' or 'omit', got {nan_policy!r}")
    if nan_policy == "raise":
        raise InvalidFrame(
            f"frame: {bad} of {total} samples inside the aperture are NaN or infinite; "
            "expected finite values (use nan_policy='omit' to fit without them)"
        )
    if total - bad <= columns:
        raise InvalidFrame(
            f"frame: only {total - bad} finite samples inside the aperture; expected "
            f"more than the {columns} fitted terms"
        )
