"""Which lenslets count: the threshold rule of the centre of gravity (relative to each window's
peak or absolute), the lenslets a mask leaves usable, and the one rule for a lit lenslet.

A lenslet is lit when its thresholded spot is valid (usable, above the minimum intensity,
finite) and holds at least a fraction of a typical full spot, the 90th percentile of the
valid spots' intensities: a lenslet partly shadowed (by the pupil's edge, an obscuration, a
region that went dark) gets light in proportion to its lit area and reports the mean slope
over that part only, which a modal model of the whole cell does not describe
(:func:`lit_lenslets`).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import finite_float
from .lattice import LensletLattice

__all__ = ["TYPICAL_SPOT_PERCENTILE", "ThresholdKind", "lit_lenslets"]

ThresholdKind = Literal["relative", "absolute"]

#: The typical full spot: this percentile of the valid spots' thresholded intensities.
TYPICAL_SPOT_PERCENTILE = 90.0


def lit_lenslets(intensity: NDArray[np.float64], valid: NDArray[np.bool_], fraction: float) -> NDArray[np.bool_]:
    """The lit lenslets: valid, and at least ``fraction`` of a typical full spot (module notes).

    Parameters
    ----------
    intensity : ndarray, shape (L,)
        Thresholded spot intensities, counts (:attr:`SpotMeasurement.intensity`).
    valid : ndarray of bool, shape (L,)
        Usable spots (:attr:`SpotMeasurement.valid`, restricted to the pupil by the caller).
    fraction : float
        In ``[0, 1]``.

    Returns
    -------
    ndarray of bool, shape (L,)
        All False when no spot is valid.

    Examples
    --------
    >>> import numpy as np
    >>> lit_lenslets(np.array([100.0, 98.0, 60.0, 101.0, 5.0]), np.array([True, True, True, True, False]), 0.9)
    array([ True,  True, False,  True, False])
    """
    if not valid.any():
        return valid.copy()
    typical = float(np.percentile(intensity[valid], TYPICAL_SPOT_PERCENTILE))
    return valid & (intensity >= fraction * typical)


def _usable_lenslets(grid: LensletLattice, frame_shape: tuple[int, int], mask: ArrayLike | None) -> NDArray[np.bool_]:
    """Lenslets whose centre is inside the mask (pixel mask) or flagged (one flag per lenslet, ``(L,)``)."""
    if mask is None:
        return np.ones(grid.count, dtype=bool)
    flags = np.asarray(mask)
    if flags.dtype != np.bool_:
        raise ValueError(f"mask must be a boolean array, got dtype {flags.dtype}")
    if flags.shape == (grid.count,):
        return flags.copy()
    if flags.shape == tuple(frame_shape):
        centres = grid.centres()
        col = np.clip(np.rint(centres[:, 0]).astype(np.intp), 0, frame_shape[1] - 1)
        row = np.clip(np.rint(centres[:, 1]).astype(np.intp), 0, frame_shape[0] - 1)
        return flags[row, col]
    raise ValueError(
        f"mask must have the frame shape {tuple(frame_shape)} or one flag per lenslet ({grid.count},), "
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
