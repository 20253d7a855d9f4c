"""The lenslet grid of a Shack-Hartmann sensor on the camera: pitch, corner, size, lit lenslets,
and the windows of the lenslets (conventions in :mod:`wavestack.pipeline.shack_hartmann`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._checks import finite_float, positive_int


_MIN_PITCH_PX = 4.0  # smallest lenslet pitch accepted, pixels
_EDGE_TOL = 1e-9  # pixels: a window edge this close to a pixel centre counts as on it


@dataclass(frozen=True)
class LensletGrid:
    """A square lenslet grid as seen on the camera.

    Attributes
    ----------
    pitch_px : float
        Lenslet pitch on the camera, pixels (same along rows and columns), ``>= 4``.
    offset_px : tuple of float
        ``(col, row)`` of the outer corner (top-left) of lenslet ``(0, 0)``, pixels, in the
        pixel-centre convention (pixel ``(r, c)`` covers ``[c - 0.5, c + 0.5]``); lenslet
        ``(i, j)`` covers columns ``offset[0] + [j, j + 1) * pitch`` and rows
        ``offset[1] + [i, i + 1) * pitch``.
    shape : tuple of int
        ``(rows, cols)`` of lenslets, both ``>= 1``.

    Raises
    ------
    ValueError
        If the pitch is not a finite number ``>= 4`` pixels, the offset not two finite
        numbers, or the shape not two positive integers.
    """

    pitch_px: float
    offset_px: tuple[float, float]
    shape: tuple[int, int]

    def __post_init__(self) -> None:
        pitch = finite_float(self.pitch_px, "pitch_px")
        if pitch < _MIN_PITCH_PX:
            raise ValueError(f"pitch_px must be >= {_MIN_PITCH_PX} pixels, got {pitch!r}")
        try:
            col, row = self.offset_px
        except (TypeError, ValueError):
            raise ValueError(f"offset_px must be a pair (col, row), got {self.offset_px!r}") from None
        offset = (finite_float(col, "offset_px[0]"), finite_float(row, "offset_px[1]"))
        try:
            rows, cols = self.shape
        except (TypeError, ValueError):
            raise ValueError(f"shape must be a pair (rows, cols), got {self.shape!r}") from None
        shape = (positive_int(rows, "shape[0]"), positive_int(cols, "shape[1]"))
        object.__setattr__(self, "pitch_px", pitch)
        object.__setattr__(self, "offset_px", offset)
        object.__setattr__(self, "shape", shape)

    @property
    def count(self) -> int:
        """Number of lenslets ``L = rows * cols``."""
        return self.shape[0] * self.shape[1]

    def centres(self) -> NDArray[np.float64]:
        """Lenslet centres on the camera.

        Returns
        -------
        ndarray, shape (rows, cols, 2)
            ``(col, row)`` of each lenslet centre, pixels.
        """
        rows, cols = self.shape
        col = self.offset_px[0] + (np.arange(cols) + 0.5) * self.pitch_px
        row = self.offset_px[1] + (np.arange(rows) + 0.5) * self.pitch_px
        out = np.empty((rows, cols, 2))
        out[..., 0] = col[None, :]
        out[..., 1] = row[:, None]
        return out

    def centres_xy(self) -> NDArray[np.float64]:
        """Lenslet centres in physical coordinates, flattened row-major.

        Returns
        -------
        ndarray, shape (L, 2)
            ``(x, y) = (col, -row)`` in pixels (x right, y up), the coordinates the
            reconstructors of :mod:`wavestack.pipeline.shack_hartmann.modal` take.
        """
        centres = self.centres().reshape(-1, 2)
        return np.column_stack([centres[:, 0], -centres[:, 1]])

    def window_starts(self) -> tuple[NDArray[np.intp], NDArray[np.intp], int]:
        """Integer subaperture windows (see the module notes).

        Returns
        -------
        row_starts : ndarray of int, shape (rows,)
            First pixel row of each lenslet row's window.
        col_starts : ndarray of int, shape (cols,)
            First pixel column of each lenslet column's window.
        width : int
            Window side ``W = floor(pitch)``, pixels.
        """
        width = int(math.floor(self.pitch_px + _EDGE_TOL))
        centres = self.centres()
        half = 0.5 * width
        col_starts = np.ceil(centres[0, :, 0] - half - _EDGE_TOL).astype(np.intp)
        row_starts = np.ceil(centres[:, 0, 1] - half - _EDGE_TOL).astype(np.intp)
        return row_starts, col_starts, width

    def check_fits(self, frame_shape: tuple[int, int]) -> None:
        """Raise ValueError unless every subaperture window lies inside the frame.

        Parameters
        ----------
        frame_shape : tuple of int
            ``(rows, cols)`` of the camera frame, pixels.

        Raises
        ------
        ValueError
            Naming the grid and the frame shape when a window falls outside.
        """
        row_starts, col_starts, width = self.window_starts()
        if (
            row_starts[0] < 0
            or col_starts[0] < 0
            or row_starts[-1] + width > frame_shape[0]
            or col_starts[-1] + width > frame_shape[1]
        ):
            raise ValueError(
                f"grid {self} has windows spanning rows {row_starts[0]}..{row_starts[-1] + width - 1}"
                f" and columns {col_starts[0]}..{col_starts[-1] + width - 1}; expected them inside "
                f"the frame of shape {tuple(frame_shape)}"
            )
