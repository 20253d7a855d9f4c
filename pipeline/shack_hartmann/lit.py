"""Which lenslets count: the threshold rule of the centre of gravity (relative to each window's
peak or absolute) and the rule for a lit, usable lenslet.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import finite_float
from .grid import LensletGrid
from .lattice import LensletLattice


ThresholdKind = Literal["relative", "absolute"]


def _usable_lenslets(
    grid: LensletGrid | LensletLattice, frame_shape: tuple[int, int], mask: ArrayLike | None
) -> NDArray[np.bool_]:
    """Lenslets whose centre is inside the mask (pixel mask) or flagged (lenslet mask: the
    grid's ``(rows, cols)`` or one flag per lenslet, ``(L,)``)."""
    if mask is None:
        return np.ones(grid.count, dtype=bool)
    flags = np.asarray(mask)
    if flags.dtype != np.bool_:
        raise ValueError(f"mask must be a boolean array, got dtype {flags.dtype}")
    per_lenslet = [(grid.count,)] + ([tuple(grid.shape)] if isinstance(grid, LensletGrid) else [])
    if flags.shape in per_lenslet:
        return flags.reshape(-1).copy()
    if flags.shape == tuple(frame_shape):
        centres = grid.centres().reshape(-1, 2)
        col = np.clip(np.rint(centres[:, 0]).astype(np.intp), 0, frame_shape[1] - 1)
        row = np.clip(np.rint(centres[:, 1]).astype(np.intp), 0, frame_shape[0] - 1)
        return flags[row, col]
    shapes = " or ".join(str(shape) for shape in per_lenslet)
    raise ValueError(
        f"mask must have the frame shape {tuple(frame_shape)} or one flag per lenslet {shapes}, "
        f"got {flags.shape}"
    )


def _check_threshold(threshold: object, kind: object) -> tuple[ThresholdKind, float]:
    """Validated threshold kind and level."""
    level = finite_float(threshold, "threshold")
    if kind == "relative":
        if not 0.0 <= level < 1.0:
            raise ValueError(f"threshold must be in [0, 1) for threshold_kind='relative', got {level!r}")
        return "relative", level
    if kind == "absolute":
        return "absolute", level
    raise ValueError(f"threshold_kind must be 'relative' or 'absolute', got {kind!r}")
