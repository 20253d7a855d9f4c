"""What a dwell-time solver returns: the dwell map and the residual it predicts.

Every solver ends in :func:`make_solution`, so the prediction is computed one way for all of
them: removal = TIF convolved with the dwell (:func:`~.removal.removal_nm`), residual = surface
minus removal over the clear aperture with its piston (mean) removed, RMS and PV of that
residual (:func:`~.removal.residual_after`). A uniform layer taken off costs dwell but changes
no figure, which is why piston is removed before judging.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._inputs import read_only
from .removal import removal_nm, residual_after
from .tif import ToolInfluence


@dataclass(frozen=True)
class DwellSolution:
    """A dwell-time map and its predicted outcome.

    Attributes
    ----------
    dwell_s : NDArray[np.float64], shape (H, W)
        Dwell time per pixel (s): >= 0 everywhere, 0 outside the dwell grid. Read-only.
    removal_nm : NDArray[np.float64], shape (H, W)
        Predicted removal (nm): the TIF convolved with ``dwell_s``. Read-only.
    residual_nm : NDArray[np.float64], shape (H, W)
        Predicted surface error left (nm): surface - removal in the clear aperture, piston
        removed; NaN outside the clear aperture. Read-only.
    rms_nm, pv_nm : float
        RMS and peak-to-valley of ``residual_nm`` over the clear aperture (nm).
    total_dwell_s : float
        Sum of ``dwell_s`` (s): the machine time spent dwelling.
    solver : str
        ``"fft"`` or ``"lsq"``.
    diagnostics : Mapping[str, Any]
        Solver-specific figures (plain numbers, strings and tuples), read-only.
    """

    dwell_s: NDArray[np.float64]
    removal_nm: NDArray[np.float64]
    residual_nm: NDArray[np.float64]
    rms_nm: float
    pv_nm: float
    total_dwell_s: float
    solver: str
    diagnostics: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))


def make_solution(
    surface_nm: NDArray[np.float64],
    clear_aperture: NDArray[np.bool_],
    grid: NDArray[np.bool_],
    dwell_s: NDArray[np.float64],
    tif: ToolInfluence,
    solver: str,
    diagnostics: dict[str, Any],
) -> DwellSolution:
    """Build the solution of ``dwell_s``: enforce its invariants, predict removal and residual.

    Parameters
    ----------
    surface_nm, clear_aperture : arrays (H, W)
        The checked inputs of the solver.
    grid : NDArray[np.bool_], shape (H, W)
        The dwell grid; dwell outside it is set to 0.
    dwell_s : NDArray[np.float64], shape (H, W)
        The solver's dwell. Values below 0 are clipped to 0 (a solver leaves only round-off
        there; the amount clipped is added to the diagnostics as ``clipped_dwell_s``).
    tif : ToolInfluence
    solver : str
    diagnostics : dict
        Copied into the solution.
    """
    dwell = np.where(grid, dwell_s, 0.0)
    clipped = float(-dwell[dwell < 0].sum())
    dwell = np.maximum(dwell, 0.0)
    removed = removal_nm(dwell, tif)
    residual, rms, pv = residual_after(surface_nm, clear_aperture, removed)
    details = dict(diagnostics, clipped_dwell_s=clipped)
    return DwellSolution(
        dwell_s=read_only(dwell),
        removal_nm=read_only(removed),
        residual_nm=read_only(residual),
        rms_nm=rms,
        pv_nm=pv,
        total_dwell_s=float(dwell.sum()),
        solver=solver,
        diagnostics=MappingProxyType(details),
    )
