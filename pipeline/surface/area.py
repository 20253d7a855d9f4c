"""The measured area a surface figure is taken over: its pixels and the circle that encloses them.

Every figure of this topic is computed on the measured pixels only: nothing is filled. The
circle is the minimum enclosing circle of the pixel centres (the aperture's
``enclosing_circle``); it is the test area's axis and radius for the sphere and the rotationally
symmetric part, and the unit circle of the PVr fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..aperture import Aperture
from ..fit import Pupil

__all__ = ["MeasuredArea", "measured_area"]


@dataclass(frozen=True, eq=False)
class MeasuredArea:
    """The measured pixels of a map and their enclosing circle.

    Attributes
    ----------
    valid : ndarray of bool, shape (rows, cols)
        The measured pixels (read-only).
    flat : ndarray of int64, shape (N,)
        Their flat indices, in row-major order.
    pupil : Pupil
        The minimum enclosing circle of their centres, pixels (cx a column, cy a row).
    """

    valid: NDArray[np.bool_]
    flat: NDArray[np.int64]
    pupil: Pupil

    @property
    def pixels(self) -> int:
        """N, the number of measured pixels."""
        return int(self.flat.size)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the map."""
        rows, cols = self.valid.shape
        return int(rows), int(cols)

    def coordinates(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(x, y) of the pixels in units of the circle's radius, x right and y up, shape (N,) each."""
        rows, cols = np.divmod(self.flat, self.shape[1])
        radius = self.pupil.radius
        return (cols - self.pupil.cx) / radius, (self.pupil.cy - rows) / radius

    def values(self, surface: ArrayLike, name: str = "surface") -> NDArray[np.float64]:
        """The map's values on the measured pixels, shape (N,), float64.

        Raises
        ------
        ValueError
            If the map's shape differs from the area's or a measured pixel is not finite.
        """
        surface = np.asarray(surface)
        if surface.shape != self.valid.shape:
            raise ValueError(f"{name}: expected a map of shape {self.valid.shape}, got {surface.shape}")
        values = surface.reshape(-1)[self.flat].astype(np.float64, copy=False)
        if not np.all(np.isfinite(values)):
            bad = int(np.count_nonzero(~np.isfinite(values)))
            raise ValueError(f"{name}: {bad} measured pixels are NaN or infinite; expected finite values on "
                             "every measured pixel")
        return values

    def scatter(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Values on the measured pixels as a map, NaN elsewhere."""
        out = np.full(self.valid.size, np.nan)
        out[self.flat] = values
        return out.reshape(self.valid.shape)


def measured_area(valid: ArrayLike, *, min_pixels: int = 1) -> MeasuredArea:
    """The measured area of a validity mask.

    Parameters
    ----------
    valid : array_like of bool, shape (rows, cols)
        True where the map holds a measurement.
    min_pixels : int
        The fewest measured pixels the caller can use.

    Raises
    ------
    ValueError
        If ``valid`` is not a 2-D boolean array or has fewer than ``min_pixels`` true pixels.
    """
    mask = np.asarray(valid)
    if mask.dtype != np.bool_ or mask.ndim != 2:
        raise ValueError(f"valid: expected a 2-D boolean mask, got dtype {mask.dtype} and shape {mask.shape}")
    count = int(np.count_nonzero(mask))
    if count < min_pixels:
        raise ValueError(f"valid: {count} measured pixels; expected at least {min_pixels} for these figures")
    mask = mask.copy()
    mask.flags.writeable = False
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    flat = np.flatnonzero(mask)
    flat.flags.writeable = False
    return MeasuredArea(valid=mask, flat=flat, pupil=Pupil(cx, cy, max(radius, 0.5)))
