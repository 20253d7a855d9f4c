"""Planning the machine program: dwell points along a raster or spiral path, with the feed the machine runs.

:func:`plan_program` turns a dwell map (s per pixel, from a dwell solver) into a
:class:`~.machine_program.MachineProgram` the machine can execute, and checks it
(:func:`.check_program`).
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import real_image
from .feed import feed_profile, segment_lengths_mm
from .grid import GridFrame
from .limits import MachineLimits
from .machine_program import PATHS, MachineProgram, PathKind, PlanReport
from .path import PointLattice, raster_order, spiral_order
from .program_checks import ProgramRejected, check_program

logger = logging.getLogger(__name__)


def plan_program(
    dwell_s: ArrayLike,
    frame: GridFrame,
    limits: MachineLimits,
    *,
    path: PathKind = "raster",
    step_px: int = 1,
) -> MachineProgram:
    """Plan the machine program for a dwell map, within the machine's limits, and check it.

    The map is sampled on a lattice ``step_px`` pixels apart, each point taking the summed
    dwell of the pixels nearest to it (:class:`.path.PointLattice`), and visited along a
    serpentine raster or an Archimedean spiral (:mod:`.path`). The tool moves continuously, so
    a point's dwell is the time of the move into it and its feed ``s_k / dwell_k``
    (``step_mm / dwell_k`` on a raster). A dwell shorter than ``s_k / max_feed`` is raised to
    that floor, points the tool only crosses included, and the acceleration bound raises
    dwells further (:mod:`.feed`); both additions are in :attr:`MachineProgram.report` and the
    log. The host should predict the removal from :meth:`MachineProgram.dwell_map`.

    A floor that is uniform over the whole dwell grid is a piston over the clear aperture when
    that grid extends past the aperture by the TIF radius: every aperture pixel then sees the
    whole TIF inside the grid, so a uniform extra dwell removes a uniform depth and leaves the
    figure unchanged. The floor applied here is not uniform (it raises only the short dwells,
    and the points the tool crosses), so it changes the figure a little, which
    :meth:`MachineProgram.dwell_map` shows. A host that wants the floor to cost no figure adds
    it uniformly before planning (``step_mm / max_feed / step_px**2`` to every dwell-grid
    pixel: the piston), so that no raster point inside the grid is raised by the feed limit
    (the acceleration bound may still raise some).

    Parameters
    ----------
    dwell_s : array_like, shape (H, W)
        Requested dwell per pixel, s, finite and >= 0 (0 outside the dwell grid).
    frame : GridFrame
        The grid of ``dwell_s`` in the machine frame.
    limits : MachineLimits
    path : {"raster", "spiral"}, optional
    step_px : int, optional
        Lattice step, pixels (>= 1).

    Returns
    -------
    MachineProgram
        A program that passes :func:`.check_program` against ``limits``.

    Raises
    ------
    ValueError
        If ``dwell_s`` is not a finite, non-negative map of the frame's shape, or ``path`` or
        ``step_px`` is invalid.
    ProgramRejected
        If the map holds no dwell, or the program cannot be made to fit the limits (a point
        outside the travel, a dwell above the per-point maximum, a total above the maximum).

    Examples
    --------
    >>> frame = GridFrame((3, 3), pixel_mm=1.0)
    >>> limits = MachineLimits(10.0, 1e6, (-5.0, 5.0), (-5.0, 5.0), 5.0, 100.0)
    >>> dwell = np.zeros((3, 3)); dwell[1, 1] = 2.0; dwell[1, 2] = 0.01
    >>> program = plan_program(dwell, frame, limits)
    >>> program.x_mm.tolist(), program.dwell_s.round(6).tolist()
    ([0.0, 1.0], [2.0, 0.1])
    >>> round(program.report.floor_extra_s, 6)
    0.09
    >>> bool(np.allclose(program.dwell_map(frame)[1], [0.0, 2.0, 0.1]))
    True
    """
    requested_map = _dwell_input(dwell_s, frame)
    kind = path if path in PATHS else None
    if kind is None:
        raise ValueError(f"path must be one of {PATHS}, got {path!r}")
    lattice = PointLattice(frame.shape, step_px)
    block = lattice.block_sum(requested_map)
    order = raster_order if kind == "raster" else spiral_order
    i, j = order(block > 0)
    if i.size == 0:
        raise ProgramRejected("dwell_s", 0.0, "some dwell > 0 (the map holds none)")
    flat = i * block.shape[1] + j
    first = np.zeros(flat.size, dtype=bool)
    first[np.unique(flat, return_index=True)[1]] = True
    requested = np.where(first, block[i, j], 0.0)
    x, y = frame.to_mm(*lattice.point_px(i, j))
    step_mm = lattice.step_px * frame.pixel_mm
    profile = feed_profile(requested, segment_lengths_mm(x, y, step_mm), step_mm,
                           limits.max_feed_mm_s, limits.max_accel_mm_s2)
    report = PlanReport(
        requested_dwell_s=float(requested_map.sum()),
        floor_extra_s=profile.floor_extra_s,
        accel_extra_s=profile.accel_extra_s,
        floor_points=profile.floor_points,
        accel_points=profile.accel_points,
        skipped_points=int(block.size - np.count_nonzero(first)),
        bridge_visits=int(flat.size - np.count_nonzero(first)),
    )
    program = MachineProgram(x, y, profile.dwell_s, profile.feed_mm_s, kind, step_mm, frame.pixel_mm, report)
    logger.info("%s program: %d points, dwell %.6g s requested, +%.6g s feed floor (%d points), "
                "+%.6g s acceleration (%d points)", kind, x.size, report.requested_dwell_s,
                report.floor_extra_s, report.floor_points, report.accel_extra_s, report.accel_points)
    check_program(program, limits)
    return program


def _dwell_input(dwell_s: ArrayLike, frame: GridFrame) -> NDArray[np.float64]:
    dwell = np.asarray(real_image(dwell_s, "dwell_s"), dtype=np.float64)
    if dwell.shape != frame.shape:
        raise ValueError(f"dwell_s has shape {dwell.shape}; expected the frame's {frame.shape}")
    bad = np.flatnonzero(~np.isfinite(dwell) | (dwell < 0))
    if bad.size:
        r, c = divmod(int(bad[0]), frame.shape[1])
        raise ValueError(f"dwell_s[{r}, {c}] is {dwell[r, c]!r}; expected a finite dwell >= 0 s")
    return dwell
