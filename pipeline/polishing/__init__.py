"""Polishing math: the tool influence function, removal, the dwell grid and the dwell-time solvers.

Computer-controlled optical surfacing removes material by dwelling a tool over the surface;
removal = TIF convolved with the dwell-time map (Preston's law; Jones, Appl. Opt. 16, 218, 1977).
Units: heights and removal in nm of surface (removal positive = surface lowered), time in s,
rates in nm/s, the grid the camera's pixel grid.

* :class:`ToolInfluence` (Gaussian from FWHM and peak rate, or a measured map);
* :func:`removal_nm`, :func:`residual_after`;
* :func:`dwell_grid` (the clear aperture grown by the TIF), :func:`extend_surface`;
* solvers, both returning a :class:`DwellSolution` with dwell >= 0:
  :func:`solve_dwell_fft` (thresholded inverse filter, RIFTA-style) and :func:`solve_dwell_lsq`
  (bounded least squares on any set of dwell points), and :func:`solve_dwell_bounded` (bounded
  least squares with FFT operators on the whole dwell grid: a Tikhonov start, projected gradient);
* the machine program: :class:`GridFrame` (pixels <-> the machine frame, mm), :class:`MachineLimits`,
  :func:`plan_program` (a raster or spiral path, feed from dwell, the feed floor and acceleration
  bound), :class:`MachineProgram` with its :class:`PlanReport`, and :func:`check_program`
  (raises :class:`ProgramRejected` naming the first violation).
"""

from __future__ import annotations

from .bounded_solver import solve_dwell_bounded
from .extension import dwell_grid, extend_surface
from .fft_solver import solve_dwell_fft
from .grid import GridFrame
from .limits import MachineLimits
from .machine_program import MachineProgram, PlanReport
from .program import plan_program
from .program_checks import ProgramRejected, check_program
from .lsq_solver import solve_dwell_lsq
from .removal import removal_nm, residual_after
from .solution import DwellSolution
from .tif import ToolInfluence

__all__ = [
    "DwellSolution",
    "GridFrame",
    "MachineLimits",
    "MachineProgram",
    "PlanReport",
    "ProgramRejected",
    "ToolInfluence",
    "check_program",
    "plan_program",
    "dwell_grid",
    "extend_surface",
    "removal_nm",
    "residual_after",
    "solve_dwell_bounded",
    "solve_dwell_fft",
    "solve_dwell_lsq",
]
