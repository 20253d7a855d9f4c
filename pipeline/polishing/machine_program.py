"""A machine program as a value: dwell points in the machine frame with their dwell and feed.

:meth:`MachineProgram.dwell_map` gives back the dwell the machine actually executes on the grid,
so that the host predicts the removal from what it sends, not from the solver's ideal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .grid import GridFrame

PathKind = Literal["raster", "spiral"]
PATHS: tuple[PathKind, ...] = ("raster", "spiral")
"""The path kinds a program may declare."""

_SNAP_PX = 1e-6  # positions this close to a pixel centre are on it (rounding of mm <-> px)


@dataclass(frozen=True)
class PlanReport:
    """What planning changed between the requested dwell and the executed one.

    Attributes
    ----------
    requested_dwell_s : float
        Sum of the requested dwell map, s.
    floor_extra_s : float
        Dwell added by the feed floor (a point cannot take less than ``s_k / max_feed``), s.
    accel_extra_s : float
        Dwell added by the acceleration bound, s.
    floor_points, accel_points : int
        Points the floor raised, and points the acceleration bound raised further.
    skipped_points : int
        Lattice points without dwell that the path never crosses.
    bridge_visits : int
        Extra visits of points already in the program, where the path crosses them again at full
        feed (spiral only).
    """

    requested_dwell_s: float
    floor_extra_s: float
    accel_extra_s: float
    floor_points: int
    accel_points: int
    skipped_points: int
    bridge_visits: int


@dataclass(frozen=True, eq=False)
class MachineProgram:
    """Dwell points in the machine frame with their dwell and the feed into each.

    Built by :func:`~.program.plan_program`; any program (also one made by hand) is checked by
    :func:`.check_program` before it is sent. The arrays are stored read-only as float64 and
    are not validated here, so that a broken program can be held and refused by the check.

    Attributes
    ----------
    x_mm, y_mm : ndarray of float64, shape (K,)
        Point positions, mm (x right, y up, origin at the grid centre).
    dwell_s : ndarray of float64, shape (K,)
        Dwell at each point: the time of the move into it, s.
    feed_mm_s : ndarray of float64, shape (K,)
        Feed on the move into each point, mm/s (``step_mm / dwell_s`` on a raster).
    path : {"raster", "spiral"}
    step_mm : float
        Lattice step, mm (``step_px * pixel_mm``).
    pixel_mm : float
        Pixel of the grid the program was planned on, mm.
    report : PlanReport or None
        What planning added (None for a program not made by :func:`~.program.plan_program`).

    Examples
    --------
    >>> program = MachineProgram([0.0, 1.0], [0.0, 0.0], [0.5, 0.25], [2.0, 4.0], "raster", 1.0, 1.0)
    >>> program.total_dwell_s
    0.75
    >>> program.dwell_map(GridFrame((1, 3), pixel_mm=1.0)).tolist()
    [[0.0, 0.5, 0.25]]
    """

    x_mm: NDArray[np.float64]
    y_mm: NDArray[np.float64]
    dwell_s: NDArray[np.float64]
    feed_mm_s: NDArray[np.float64]
    path: PathKind
    step_mm: float
    pixel_mm: float
    report: PlanReport | None = field(default=None)

    def __post_init__(self) -> None:
        for name in ("x_mm", "y_mm", "dwell_s", "feed_mm_s"):
            values = np.array(getattr(self, name), dtype=np.float64)
            values.setflags(write=False)
            object.__setattr__(self, name, values)
        for name in ("step_mm", "pixel_mm"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def total_dwell_s(self) -> float:
        """Sum of the dwell, s: the program's run time."""
        return float(np.sum(self.dwell_s))

    def dwell_map(self, frame: GridFrame) -> NDArray[np.float64]:
        """The dwell the machine executes, on the grid: each point's dwell at its position.

        A point between pixel centres (an even lattice step) shares its dwell among the
        neighbouring pixels by bilinear weights, which keeps the total and the centroid.

        Parameters
        ----------
        frame : GridFrame
            The grid the program was planned on (same ``pixel_mm``).

        Returns
        -------
        ndarray of float64, shape frame.shape
            Executed dwell per pixel, s; sums to :attr:`total_dwell_s`.

        Raises
        ------
        ValueError
            If the frame's pixel differs from the program's, or a point lies off the grid.
        """
        if not math.isclose(frame.pixel_mm, self.pixel_mm, rel_tol=1e-9):
            raise ValueError(f"frame.pixel_mm is {frame.pixel_mm}; expected the program's {self.pixel_mm}")
        rows, cols = frame.to_px(self.x_mm, self.y_mm)
        out = np.zeros(frame.shape, dtype=np.float64)
        weights_r, weights_c = _bilinear(rows, frame.shape[0], "row"), _bilinear(cols, frame.shape[1], "column")
        for (ri, wr) in weights_r:
            for (ci, wc) in weights_c:
                np.add.at(out, (ri, ci), self.dwell_s * wr * wc)
        return out


def _bilinear(pos: NDArray[np.float64], n: int, axis: str) -> list[tuple[NDArray[np.intp], NDArray[np.float64]]]:
    snapped = np.where(np.abs(pos - np.rint(pos)) < _SNAP_PX, np.rint(pos), pos)
    off = np.flatnonzero(~((snapped >= 0) & (snapped <= n - 1)))
    if off.size:
        k = int(off[0])
        raise ValueError(f"point {k} is at {axis} {pos[k]:.6g}, off the grid (0 .. {n - 1})")
    lo = np.floor(snapped).astype(np.intp)
    frac = snapped - lo
    hi = np.minimum(lo + 1, n - 1)
    return [(lo, 1.0 - frac), (hi, frac)]
