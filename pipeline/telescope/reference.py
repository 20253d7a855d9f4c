"""The interferometer reference's tilt: what an operator sets at each field point to centre the return spot.

At a field point the operator tips and tilts the interferometer's reference (or follows the image
laterally) until the return spot is centred, which nulls the fringes' tilt. :func:`centring_tilt`
is that setting, the map's least-squares plane rounded to the reference mount's step
(:data:`TILT_RESOLUTION`); :class:`ReferenceTilt` is the setting as a value and its plane on the
camera grid (x right along +col, y up along -row, about the grid's centre). Both the controller
(whether the camera resolves the fringes, ``wavestack.align.fringes``) and the simulated bench
(which puts the rest of the wavefront on the station's optic) follow this one convention.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["TILT_RESOLUTION", "ReferenceTilt", "centring_tilt"]

#: The reference mount's tilt step, waves per camera pixel (a fringe every 1000 pixels).
TILT_RESOLUTION = 1e-3


@dataclass(frozen=True)
class ReferenceTilt:
    """The tip/tilt the interferometer's reference was set to for one refresh, waves per camera pixel.

    ``x_per_px`` along +col (x right), ``y_per_px`` along -row (y up).

    Example
    -------
    >>> ReferenceTilt(0.5, 0.0).plane((2, 3)).tolist()
    [[-0.5, 0.0, 0.5], [-0.5, 0.0, 0.5]]
    """

    x_per_px: float = 0.0
    y_per_px: float = 0.0

    def plane(self, shape: tuple[int, int]) -> NDArray[np.float64]:
        """The tilt as a map about the grid's centre, waves, shape ``shape``."""
        rows, cols = np.mgrid[: shape[0], : shape[1]]
        return self.x_per_px * (cols - (shape[1] - 1) / 2) + self.y_per_px * ((shape[0] - 1) / 2 - rows)


def centring_tilt(waves: NDArray[np.floating], resolution: float = TILT_RESOLUTION) -> ReferenceTilt:
    """The reference tilt that centres the return spot: the map's least-squares plane, rounded.

    The spot's centroid is the mean wavefront slope; the least-squares plane over the pupil is
    the same to the precision a centring needs. Rounded to ``resolution`` waves per pixel (the
    reference mount's step): the loop adds back the tilt *set*, not the wavefront's own.

    Example
    -------
    >>> t = centring_tilt(ReferenceTilt(0.3, -0.2).plane((8, 16)) + 5.0)
    >>> round(t.x_per_px, 6), round(t.y_per_px, 6)
    (0.3, -0.2)
    """
    values = np.asarray(waves, dtype=np.float64)
    rows, cols = np.nonzero(np.isfinite(values))
    if rows.size < 3:
        return ReferenceTilt()
    x = cols - (values.shape[1] - 1) / 2
    y = (values.shape[0] - 1) / 2 - rows
    design = np.column_stack([np.ones(rows.size), x, y])
    (_, sx, sy), *_ = np.linalg.lstsq(design, values[rows, cols], rcond=None)
    return ReferenceTilt(float(np.round(sx / resolution) * resolution), float(np.round(sy / resolution) * resolution))
