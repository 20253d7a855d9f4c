"""Angles: the one principal-value wrap shared by the phase and map code.

(:mod:`wavestack.pipeline.phase.spatial_unwrap` keeps its own in-place variant, which reuses buffers on the
per-frame path.)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def wrap_angle(angle: ArrayLike) -> NDArray[np.float64]:
    """Principal value of an angle in radians, in (-pi, pi]; NaN stays NaN.

    Parameters
    ----------
    angle : array_like
        Radians, any shape.

    Returns
    -------
    ndarray of float64, same shape
    """
    return np.pi - np.mod(np.pi - np.asarray(angle, dtype=np.float64), 2.0 * np.pi)
