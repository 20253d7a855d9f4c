"""Residues, wrap counts and connected components of a wrapped phase map.

The pieces spatial (:mod:`wavestack.pipeline.phase.spatial_unwrap`) and temporal
(:mod:`wavestack.pipeline.phase.temporal_unwrap`) unwrapping share. A residue is a 2 x 2 loop
of pixels whose wrapped differences do not add up to zero (Goldstein, Zebker and Werner,
Radio Science 23(4), 713-720, 1988).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage


_TWO_PI = 2.0 * math.pi


def _wrap(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """``values - 2 pi rint(values / 2 pi)`` in a new array (NaN stays NaN)."""
    turns = np.multiply(values, 1.0 / _TWO_PI)
    np.rint(turns, out=turns)
    turns *= _TWO_PI
    return np.subtract(values, turns, out=turns)


def _wrap_counts(field_: NDArray[np.float64]) -> tuple[NDArray[np.int8], NDArray[np.int8]]:
    """Signed 2 pi wrap counts of the horizontal and vertical differences of a wrapped field.

    ``field_`` must lie in ``[-pi, pi]`` (NaN at invalid pixels); the counts are then -1, 0
    or +1 (the sign of the difference where it exceeds pi in magnitude) and 0 on every edge
    touching a NaN. Shapes ``(rows, cols - 1)`` and ``(rows - 1, cols)``.
    """
    single = field_.astype(np.float32)
    limit = np.float32(math.pi)
    counts = []
    for diff in (single[:, 1:] - single[:, :-1], single[1:, :] - single[:-1, :]):
        up = np.greater(diff, limit).view(np.int8)
        down = np.less(diff, -limit).view(np.int8)
        counts.append(np.subtract(up, down))
    return counts[0], counts[1]


def _count_residues(values: NDArray[np.float64], valid: NDArray[np.bool_]) -> int:
    """Residues of a validated wrapped map inside its mask."""
    wraps_x, wraps_y = _wrap_counts(_wrap(np.where(valid, values, np.nan)))
    return _residues(wraps_x, wraps_y, _loop_mask(valid))


def _residues(
    wraps_x: NDArray[np.int8], wraps_y: NDArray[np.int8], loops: NDArray[np.bool_]
) -> int:
    """Count loops (valid per ``loops``) with a non-zero circulation of wrap counts.

    The raw differences around a loop cancel, so the sum of the wrapped differences is
    ``-2 pi`` times the sum of the wrap counts: a residue is a loop where that sum is not 0.
    """
    circulation = wraps_x[:-1, :] - wraps_x[1:, :]
    circulation += wraps_y[:, 1:]
    circulation -= wraps_y[:, :-1]
    return int(np.count_nonzero(np.logical_and(circulation, loops)))


def _loop_mask(valid: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """2 x 2 loops whose four pixels are valid, shape (rows - 1, cols - 1)."""
    loops = valid[:-1, :-1] & valid[1:, :-1]
    loops &= valid[:-1, 1:]
    loops &= valid[1:, 1:]
    return loops


def _components(valid: NDArray[np.bool_]) -> tuple[NDArray[np.int32], int]:
    """4-connected components of the mask: labels (0 = invalid) and their number."""
    count, labels = cv2.connectedComponents(
        valid.astype(np.uint8), connectivity=4, ltype=cv2.CV_32S
    )
    return np.asarray(labels, dtype=np.int32), int(count) - 1


def _shift_components(
    phase: NDArray[np.float64],
    labels: NDArray[np.int32],
    count: int,
    reference: NDArray[np.float64] | None,
    reference_valid: NDArray[np.bool_] | None,
) -> NDArray[np.float64]:
    """Shift each component by 2 pi k so the median of (phase - reference) is in [-pi, pi).

    Without a reference, or for a component sharing no valid pixel with it, the median of
    the phase itself is used.
    """
    index = np.arange(1, count + 1)
    medians = _label_medians(phase, labels, index)
    if reference is not None and reference_valid is not None:
        shared_labels = np.where(reference_valid, labels, 0)
        shared = np.bincount(shared_labels.ravel(), minlength=count + 1)[1:] > 0
        if shared.any():
            with np.errstate(invalid="ignore"):
                offsets = phase - reference
            medians[shared] = _label_medians(offsets, shared_labels, index[shared])
    turns = np.floor((medians + math.pi) / _TWO_PI)
    if not turns.any():
        return phase
    shift = np.concatenate(([0.0], _TWO_PI * turns))
    return phase - shift[labels]


def _label_medians(
    values: NDArray[np.float64], labels: NDArray[np.int32], index: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Median of ``values`` over each label in ``index`` (every label must have pixels)."""
    if index.size == 1:  # the usual single pupil: a plain median is ~10x faster
        return np.array([np.median(values[labels == index[0]])])
    return np.asarray(ndimage.median(values, labels, index), dtype=np.float64).reshape(-1)
