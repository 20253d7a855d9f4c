"""The machine frame of the shared pixel grid: pixel indices to millimetres on the optic and back.

The surface, the measurement, the dwell map and the simulated optic share one grid, the camera's
pixel grid of shape (H, W) with square pixels of ``pixel_mm`` on the optic. The machine frame has
x to the right, y up and its origin at the grid centre (issue 14 contracts)::

    x_mm = (col - (W - 1) / 2) * pixel_mm
    y_mm = ((H - 1) / 2 - row) * pixel_mm
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float, positive_int


@dataclass(frozen=True)
class GridFrame:
    """The pixel grid of shape (H, W) placed in the machine frame (x right, y up, origin at the centre).

    Attributes
    ----------
    shape : tuple of int
        (H, W), pixels; both >= 1.
    pixel_mm : float
        Side of one square pixel on the optic, mm; > 0.

    Examples
    --------
    >>> frame = GridFrame((3, 5), pixel_mm=0.5)
    >>> x, y = frame.to_mm([0, 2], [0, 4])      # top-left and bottom-right pixels
    >>> x.tolist(), y.tolist()
    ([-1.0, 1.0], [0.5, -0.5])
    >>> rows, cols = frame.to_px(x, y)
    >>> rows.tolist(), cols.tolist()
    ([0.0, 2.0], [0.0, 4.0])
    """

    shape: tuple[int, int]
    pixel_mm: float

    def __post_init__(self) -> None:
        shape = tuple(self.shape)
        if len(shape) != 2:
            raise ValueError(f"shape must be (H, W), got {self.shape!r}")
        h = positive_int(shape[0], "shape[0] (H)")
        w = positive_int(shape[1], "shape[1] (W)")
        object.__setattr__(self, "shape", (h, w))
        object.__setattr__(self, "pixel_mm", positive_float(self.pixel_mm, "pixel_mm"))

    @property
    def centre_px(self) -> tuple[float, float]:
        """(row, col) of the machine origin, pixels: ((H - 1) / 2, (W - 1) / 2)."""
        return ((self.shape[0] - 1) / 2.0, (self.shape[1] - 1) / 2.0)

    def to_mm(self, rows: ArrayLike, cols: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Machine coordinates of (fractional) pixel positions.

        Parameters
        ----------
        rows, cols : array_like, broadcastable
            Pixel row and column indices (fractions allowed; 0 is the first row / column).

        Returns
        -------
        x_mm, y_mm : ndarray of float64, the broadcast shape
            x to the right, y up, origin at the grid centre, mm.
        """
        r = np.asarray(rows, dtype=np.float64)
        c = np.asarray(cols, dtype=np.float64)
        row0, col0 = self.centre_px
        return (c - col0) * self.pixel_mm, (row0 - r) * self.pixel_mm

    def to_px(self, x_mm: ArrayLike, y_mm: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Fractional pixel positions of machine coordinates (the inverse of :meth:`to_mm`).

        Parameters
        ----------
        x_mm, y_mm : array_like, broadcastable
            Machine coordinates, mm.

        Returns
        -------
        rows, cols : ndarray of float64, the broadcast shape
            Pixel row and column positions, not rounded (a position may lie off the grid).
        """
        x = np.asarray(x_mm, dtype=np.float64)
        y = np.asarray(y_mm, dtype=np.float64)
        row0, col0 = self.centre_px
        return row0 - y / self.pixel_mm, col0 + x / self.pixel_mm
