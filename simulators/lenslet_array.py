"""The geometry of a simulated lenslet array: where its lenslets sit, their cells, how many fit.

Written here from the array's description, apart from the pipeline's
:class:`~wavestack.pipeline.shack_hartmann.LensletLattice` (a simulator shares no geometry code
with what it is tested against). Positions are ``(col, row)`` pixels. The array has ``rows x
cols`` lenslets numbered row-major, ``k = i * cols + j``; lenslet ``(0, 0)`` is centred at
``offset + pitch / 2`` along both axes; row ``i`` runs along the unit vector ``r = (cos t, sin
t)`` (``t`` the orientation) and rows are stacked along ``s = (-sin t, cos t)``: lenslet ``(i,
j)`` is centred at ``first + pitch (j + h_i) r + q i s`` with ``h_i = 0``, ``q = pitch`` for a
square array and ``h_i = (i mod 2) / 2``, ``q = pitch sqrt(3) / 2`` for a hexagonal one. A
lenslet's cell is the square of side ``pitch`` turned with the array, or the regular hexagon whose
edges lie half a pitch from the centre across ``r`` and the two directions 60 degrees from it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

class LensletArray:
    """A simulated lenslet array's geometry (module notes).

    Parameters
    ----------
    pitch_px : float
        Lenslet pitch on the camera, pixels.
    offset_px : (float, float)
        Lenslet (0, 0) is centred at ``offset_px + pitch_px / 2`` along both axes.
    lattice : {"square", "hexagonal"}
    orientation_deg : float
        Angle of the rows from the camera's columns towards its rows, degrees.
    """

    def __init__(self, pitch_px: float, offset_px: tuple[float, float], lattice: str, orientation_deg: float) -> None:
        self.pitch = float(pitch_px)
        self.hexagonal = lattice == "hexagonal"
        angle = math.radians(orientation_deg)
        self.along = np.array([math.cos(angle), math.sin(angle)])  # a row's direction, (d_col, d_row)
        self.across = np.array([-math.sin(angle), math.cos(angle)])  # the next row's side
        self.row_step = self.pitch * (math.sqrt(3.0) / 2.0 if self.hexagonal else 1.0)
        self.first = np.asarray(offset_px, dtype=np.float64) + 0.5 * self.pitch
        self.offset = tuple(offset_px)

    def centres(self, shape: tuple[int, int]) -> NDArray[np.float64]:
        """Centres ``(col, row)`` of a ``rows x cols`` array, row-major, shape (rows * cols, 2)."""
        i, j = np.divmod(np.arange(shape[0] * shape[1]), shape[1])
        stagger = 0.5 * (i % 2) if self.hexagonal else 0.0
        return (self.first + (self.pitch * (j + stagger))[:, None] * self.along
                + (self.row_step * i)[:, None] * self.across)

    def _cell_normals(self) -> NDArray[np.float64]:
        """Unit normals of the cell's edge pairs: each edge lies half a pitch from the centre along one."""
        if not self.hexagonal:
            return np.array([self.along, self.across])
        sixty = 0.5 * self.along + 0.5 * math.sqrt(3.0) * self.across
        return np.array([self.along, sixty, sixty - self.along])

    def cell_nodes(self, per_pitch: int) -> NDArray[np.float64]:
        """Midpoint nodes ``(d_col, d_row)`` of one cell: ``per_pitch`` per pitch along ``r`` and ``s``."""
        reach = 2 * per_pitch  # a cell reaches at most pitch / sqrt(2) < pitch from its centre
        phase = 0.5 if per_pitch % 2 == 0 else 0.0  # midpoints of per_pitch equal parts of the pitch
        steps = ((np.arange(-reach, reach + 1) + phase) / per_pitch) * self.pitch
        u, v = np.meshgrid(steps, steps, indexing="ij")
        nodes = u.reshape(-1, 1) * self.along + v.reshape(-1, 1) * self.across
        inside = np.all(np.abs(nodes @ self._cell_normals().T) < 0.5 * self.pitch, axis=1)
        return nodes[inside]

    def _fits(self, centres: NDArray[np.float64], size: tuple[int, int]) -> NDArray[np.bool_]:
        """Cells inside the frame, whose pixel centres are integers: within ``[-0.5, size - 0.5]``."""
        sides = 4 if not self.hexagonal else 6
        radius = self.pitch / math.sqrt(2.0) if not self.hexagonal else self.pitch / math.sqrt(3.0)
        theta = np.radians(np.arange(sides) * 360.0 / sides + 180.0 / sides)
        corners = radius * (np.cos(theta)[:, None] * self.along + np.sin(theta)[:, None] * self.across)
        half = np.abs(corners).max(axis=0)  # half the cell's extent along the columns and the rows
        limit = np.array([size[1], size[0]]) - 0.5
        return np.all((centres - half >= -0.5) & (centres + half <= limit), axis=1)

    def shape_in(self, size: tuple[int, int], wanted: tuple[int, int] | None) -> tuple[int, int]:
        """The array's ``(rows, cols)``: ``wanted`` when every cell fits, else the most that do.

        Raises
        ------
        ValueError
            If ``wanted`` does not fit in the frame, or no lenslet does.
        """
        height, width = size
        if wanted is not None:
            shape = (int(wanted[0]), int(wanted[1]))
            if not self._fits(self.centres(shape), size).all():
                raise ValueError(f"grid_shape: {shape} lenslets of pitch {self.pitch} px from {self.offset} do "
                                 f"not all fit in the {height} x {width} frame")
            return shape
        reach = int(2 * math.hypot(height, width) / self.pitch) + 2
        fits = self._fits(self.centres((reach, reach)), size).reshape(reach, reach)
        cols = int(np.argmin(np.append(fits[: 2 if self.hexagonal else 1].all(axis=0), False)))
        rows = int(np.argmin(np.append(fits[:, :cols].all(axis=1), False))) if cols else 0
        if rows < 1 or cols < 1:
            raise ValueError(f"grid_shape: no whole lenslet of pitch {self.pitch} px from {self.offset} fits in the "
                             f"{height} x {width} frame")
        return rows, cols
