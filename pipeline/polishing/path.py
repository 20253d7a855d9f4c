"""Where the tool goes: the lattice of dwell points on the pixel grid and the order it visits them.

A dwell map of shape (H, W) is sampled on a square lattice of points ``step_px`` pixels apart,
centred on the grid; every pixel belongs to its nearest point, and the dwell of the pixels a
point stands for is summed into it (:meth:`PointLattice.block_sum`). Two orders visit the points:

* :func:`raster_order`, a serpentine (boustrophedon) raster: rows top to bottom, alternately
  left to right and right to left, every move one lattice step (along the row, or down at the
  turn column). Rows above the first and below the last row with dwell are left out, and each
  row is trimmed to the columns between its own points with dwell and the turn columns it
  shares with its neighbours; the points kept that have no dwell are crossed at full feed.
* :func:`spiral_order`, an Archimedean spiral ``r = theta / (2 pi)`` lattice steps around the
  centre of the points with dwell: every lattice point inside the disc that reaches the farthest
  point with dwell, ordered by the spiral turn it lies nearest to and its angle on that turn.
  Where a turn leaves the lattice or the disc (its outer turns are only partly filled), the
  gap is bridged by the lattice points on the straight line across it: the tool crosses them
  at full feed, so they are visited a second time, and that visit is in the program too.

Leaving out points is safe only because the tool never crosses them: every move of both orders
runs between neighbouring points (at most one step along each axis) that are both in the
program, so the dwell the tool spends anywhere is a point's dwell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._checks import positive_int


@dataclass(frozen=True)
class PointLattice:
    """A square lattice of dwell points ``step_px`` pixels apart, centred on an (H, W) grid.

    Point (i, j) stands at pixel row ``row0_px + i * step_px`` and column
    ``col0_px + j * step_px`` (fractions of a pixel when the spare pixels are odd); there are
    ``ceil(H / step_px)`` by ``ceil(W / step_px)`` points, all on the grid.

    Attributes
    ----------
    shape : tuple of int
        (H, W) of the pixel grid.
    step_px : int
        Lattice step, pixels (>= 1; 1 keeps every pixel a point).

    Examples
    --------
    >>> lattice = PointLattice((5, 4), step_px=2)
    >>> lattice.points_shape, lattice.row0_px, lattice.col0_px
    ((3, 2), 0.0, 0.5)
    >>> lattice.block_sum(np.ones((5, 4))).tolist()
    [[2.0, 2.0], [4.0, 4.0], [4.0, 4.0]]
    """

    shape: tuple[int, int]
    step_px: int

    def __post_init__(self) -> None:
        h, w = (positive_int(n, "shape") for n in self.shape)
        object.__setattr__(self, "shape", (h, w))
        object.__setattr__(self, "step_px", positive_int(self.step_px, "step_px"))

    @property
    def points_shape(self) -> tuple[int, int]:
        """(rows, cols) of lattice points: ``ceil(H / step_px)``, ``ceil(W / step_px)``."""
        return (-(-self.shape[0] // self.step_px), -(-self.shape[1] // self.step_px))

    @property
    def row0_px(self) -> float:
        """Pixel row of the first lattice row (the lattice is centred on the grid)."""
        return _offset(self.shape[0], self.points_shape[0], self.step_px)

    @property
    def col0_px(self) -> float:
        """Pixel column of the first lattice column."""
        return _offset(self.shape[1], self.points_shape[1], self.step_px)

    def point_px(self, i: NDArray[np.intp], j: NDArray[np.intp]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Pixel (row, col) positions of lattice points (i, j), fractional."""
        return (self.row0_px + np.asarray(i) * self.step_px, self.col0_px + np.asarray(j) * self.step_px)

    def block_sum(self, dwell_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sum a (H, W) map into the lattice points: each pixel goes to its nearest point.

        Parameters
        ----------
        dwell_s : ndarray, shape (H, W)

        Returns
        -------
        ndarray of float64, shape ``points_shape``
            Per-point sums; the total is the map's total.
        """
        rows = _nearest(self.shape[0], self.row0_px, self.step_px, self.points_shape[0])
        cols = _nearest(self.shape[1], self.col0_px, self.step_px, self.points_shape[1])
        n_rows, n_cols = self.points_shape
        flat = (rows[:, None] * n_cols + cols[None, :]).ravel()
        sums = np.bincount(flat, weights=np.asarray(dwell_s, dtype=np.float64).ravel(), minlength=n_rows * n_cols)
        return sums.reshape(n_rows, n_cols)


def _offset(n_px: int, n_points: int, step_px: int) -> float:
    return (n_px - 1 - (n_points - 1) * step_px) / 2.0


def _nearest(n_px: int, first_px: float, step_px: int, n_points: int) -> NDArray[np.intp]:
    index = np.floor((np.arange(n_px) - first_px) / step_px + 0.5).astype(np.intp)
    return np.clip(index, 0, n_points - 1)


def raster_order(has_dwell: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Serpentine raster through the lattice rows that hold dwell (see the module docstring).

    Parameters
    ----------
    has_dwell : ndarray of bool, shape (rows, cols)
        Lattice points with requested dwell > 0.

    Returns
    -------
    i, j : ndarray of intp, shape (K,)
        Lattice row and column of each visited point, in visiting order; consecutive points are
        lattice neighbours. Empty when no point has dwell.

    Examples
    --------
    >>> mask = np.array([[0, 1, 0], [0, 0, 0], [1, 0, 0]], dtype=bool)
    >>> i, j = raster_order(mask)
    >>> list(zip(i.tolist(), j.tolist()))
    [(0, 1), (1, 1), (1, 0), (2, 0)]
    """
    rows = np.flatnonzero(has_dwell.any(axis=1))
    if rows.size == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    spans = []
    for r in range(int(rows[0]), int(rows[-1]) + 1):
        cols = np.flatnonzero(has_dwell[r])
        # a row without dwell between rows with dwell is crossed like the row above it
        spans.append((int(cols[0]), int(cols[-1])) if cols.size else spans[-1])
    out_i: list[NDArray[np.intp]] = []
    out_j: list[NDArray[np.intp]] = []
    start = spans[0][0]
    for k, (lo, hi) in enumerate(spans):
        after = spans[k + 1] if k + 1 < len(spans) else (lo, hi)
        if k % 2 == 0:  # left to right, turning down at the rightmost column either row needs
            end = max(hi, after[1])
            cols = np.arange(start, end + 1)
        else:
            end = min(lo, after[0])
            cols = np.arange(start, end - 1, -1)
        out_j.append(cols)
        out_i.append(np.full(cols.size, int(rows[0]) + k, np.intp))
        start = end
    return np.concatenate(out_i), np.concatenate(out_j).astype(np.intp)


def spiral_order(has_dwell: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Lattice points ordered along an Archimedean spiral of one lattice step pitch, from the centre out.

    The centre is the middle of the bounding box of the points with dwell; every lattice point
    within the radius of the farthest point with dwell is visited (those without dwell at full
    feed). A point at radius r and angle theta (turns, in [0, 1)) lies on turn
    ``n = max(round(r - theta), 0)``; points are ordered by ``n + theta``, then by r.

    Parameters
    ----------
    has_dwell : ndarray of bool, shape (rows, cols)

    Returns
    -------
    i, j : ndarray of intp, shape (K,)
        Lattice row and column of each visit, in visiting order; consecutive visits differ by
        at most one step along each axis; a point may be visited more than once (bridges).
        Empty when no point has dwell.

    Examples
    --------
    >>> i, j = spiral_order(np.ones((3, 3), dtype=bool))
    >>> (int(i[0]), int(j[0])), len(set(zip(i.tolist(), j.tolist()))), len(i)  # 2 bridging visits
    ((1, 1), 9, 11)
    """
    ii, jj = np.nonzero(has_dwell)
    if ii.size == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    ci = (ii.min() + ii.max()) / 2.0
    cj = (jj.min() + jj.max()) / 2.0
    reach = float(np.max(np.hypot(ii - ci, jj - cj))) + 1e-9
    gi, gj = np.indices(has_dwell.shape)
    dx, dy = (gj - cj).ravel(), (ci - gi).ravel()  # x right, y up
    radius = np.hypot(dx, dy)
    inside = radius <= reach
    dx, dy, radius = dx[inside], dy[inside], radius[inside]
    turns = np.mod(np.arctan2(dy, dx) / (2.0 * math.pi), 1.0)
    ring = np.maximum(np.rint(radius - turns), 0.0)
    order = np.lexsort((radius, ring + turns))
    return _bridged(gi.ravel()[inside][order], gj.ravel()[inside][order])


def _bridged(i: NDArray[np.intp], j: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Insert the lattice points on the line across every move longer than one step per axis."""
    jumps = np.maximum(np.abs(np.diff(i)), np.abs(np.diff(j)))
    long_moves = np.flatnonzero(jumps > 1)
    if long_moves.size == 0:
        return i.astype(np.intp), j.astype(np.intp)
    pieces_i, pieces_j, start = [], [], 0
    for k in long_moves.tolist():  # the move from visit k to visit k + 1
        n = int(jumps[k])
        t = np.arange(1, n) / n
        pieces_i += [i[start:k + 1], np.rint(i[k] + t * (i[k + 1] - i[k]))]
        pieces_j += [j[start:k + 1], np.rint(j[k] + t * (j[k + 1] - j[k]))]
        start = k + 1
    pieces_i.append(i[start:])
    pieces_j.append(j[start:])
    return np.concatenate(pieces_i).astype(np.intp), np.concatenate(pieces_j).astype(np.intp)
