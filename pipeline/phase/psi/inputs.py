"""Checked inputs of the PSI methods: the frame stack, frame counts, directions, steps and masks.

Each helper turns one argument of the public functions of :mod:`wavestack.pipeline.phase.psi`
into the array the algorithms expect, or raises a ``ValueError`` naming the argument and what
was expected. :func:`_nominal_steps` gives the default equal steps over one cycle.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._checks import optional_mask

_MIN_SAMPLE_PIXELS = 16  # fewer pixels than this cannot estimate steps reliably
_DIRECTIONS = ("ccw", "cw")


def _frame_stack(frames: ArrayLike | Sequence[ArrayLike]) -> NDArray:
    """The frames as one (N, rows, cols) real array (no copy when already one)."""
    if isinstance(frames, np.ndarray):
        stack = frames
    else:
        if isinstance(frames, (str, bytes)):
            raise ValueError("frames: expected an (N, rows, cols) array or a sequence of 2-D arrays")
        try:
            arrays = [np.asarray(frame) for frame in frames]  # type: ignore[union-attr]
        except TypeError:
            raise ValueError(
                "frames: expected an (N, rows, cols) array or a sequence of 2-D arrays, "
                f"got {type(frames).__name__}"
            ) from None
        if not arrays:
            raise ValueError("frames: expected at least one frame, got an empty sequence")
        for index, array in enumerate(arrays):
            if array.ndim != 2:
                raise ValueError(f"frames: expected 2-D frames, frame {index} has shape {array.shape}")
            if array.shape != arrays[0].shape:
                raise ValueError(
                    f"frames: expected frames of equal shape, frame 0 is {arrays[0].shape} "
                    f"and frame {index} is {array.shape}"
                )
        stack = np.stack(arrays)
    if stack.ndim != 3:
        raise ValueError(f"frames: expected an (N, rows, cols) array, got shape {stack.shape}")
    if 0 in stack.shape:
        raise ValueError(f"frames: expected non-empty frames, got shape {stack.shape}")
    kind = stack.dtype.kind
    if kind not in "iuf":
        raise ValueError(f"frames: expected real numbers (integer or float), got dtype {stack.dtype}")
    return stack


def _require_count(stack: NDArray, allowed: str, ok: bool) -> None:
    if not ok:
        raise ValueError(f"frames: expected {allowed} frames, got {stack.shape[0]}")


def _check_direction(direction: str) -> str:
    if direction not in _DIRECTIONS:
        raise ValueError(f"direction: expected 'ccw' or 'cw', got {direction!r}")
    return direction


def _steps_array(steps: ArrayLike, count: int, name: str) -> NDArray[np.float64]:
    """``steps`` as a finite float64 vector of length ``count``."""
    try:
        array = np.asarray(steps, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {count} phase steps in radians") from None
    if array.shape != (count,):
        raise ValueError(f"{name}: expected {count} phase steps (one per frame), got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite phase steps in radians")
    return array


def _nominal_steps(count: int, direction: str) -> NDArray[np.float64]:
    """Equal steps over one cycle, ``delta_k = +-2 pi k / N``."""
    sign = 1.0 if direction == "ccw" else -1.0
    return sign * 2.0 * np.pi * np.arange(count) / count


def _mask_array(mask: ArrayLike | None, shape: tuple[int, int]) -> NDArray[np.bool_] | None:
    return optional_mask(mask, shape, min_true=_MIN_SAMPLE_PIXELS, shape_of="that of a frame")
