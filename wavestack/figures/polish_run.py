"""One PNG per polishing run: the measured surface, the dwell map, the predicted and the measured residual.

People judge a surface by looking at it: the figures show each map on the measurement grid in mm
(the machine frame of the contracts: x right, y up, origin at the grid centre), with a colour bar
in nm (surfaces) or s/mm^2 (the dwell, as a density over one lattice cell) and a title giving its RMS and PV. The two residuals share one colour
scale, so what the machine achieved reads directly against what the solver promised.
matplotlib's Agg backend (no display) through the object API (``Figure``), so nothing global is set;
the panels are drawn by :func:`~wavestack.figures.drawing.map_panel`, like every wavestack figure.
The figure reads the loop's values only (its :class:`~wavestack.polish.run_record.RunRecord` and
:class:`~wavestack.polish.run_record.RunMaps`); ``wavestack polish --plots`` hands them over.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray
from scipy import ndimage

from wavestack.figures.drawing import SIGNED_CMAP, data_limits, map_panel, new_figure, save_figure
from wavestack.polish.run_record import RunMaps, RunRecord

__all__ = ["plot_run", "run_plot_name"]


def run_plot_name(run: int) -> str:
    """``run-003.png``.

    Example
    -------
    >>> run_plot_name(3)
    'run-003.png'
    """
    return f"run-{run:03d}.png"


def _stats(values: NDArray) -> str:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return "not measured"
    return f"RMS {np.std(finite):.2f}, PV {np.ptp(finite):.1f}"


def _panel(figure: Figure, axes: Axes, data: NDArray, extent: tuple[float, float, float, float], title: str, unit: str,
           limits: tuple[float, float] | None, cmap: str) -> None:
    map_panel(figure, axes, data, title=title, unit=unit, limits=limits or data_limits(data), cmap=cmap,
              extent=extent, axis_labels=("x, mm", "y, mm"))


def plot_run(folder: Path, row: RunRecord, maps: RunMaps, *, pixel_mm: float, step_px: int = 1) -> Path:
    """Write run ``row.run``'s figure into ``folder``; returns its path.

    Parameters
    ----------
    folder : Path
        An existing folder.
    row : RunRecord
    maps : RunMaps
        NaN outside the aperture (the dwell map: 0 outside the dwell grid); a measured residual
        of None is drawn as not measured.
    pixel_mm : float
    step_px : int
        The dwell points' spacing, pixels: the dwell is drawn as a density (s/mm^2) averaged over
        one lattice cell, not as isolated points.
    """
    measured_nm, dwell_s, predicted_residual_nm = maps.measured_nm, maps.dwell_s, maps.predicted_residual_nm
    measured_residual_nm = maps.measured_residual_nm
    rows, cols = np.shape(measured_nm)
    half_w, half_h = (cols - 1) / 2 * pixel_mm, (rows - 1) / 2 * pixel_mm
    extent = (-half_w, half_w, -half_h, half_h)
    after = np.full((rows, cols), np.nan) if measured_residual_nm is None else np.asarray(measured_residual_nm)
    residuals = np.concatenate([np.ravel(predicted_residual_nm), np.ravel(after)])
    residuals = residuals[np.isfinite(residuals)]
    bound = float(np.max(np.abs(residuals))) if residuals.size else 1.0
    shared = (-bound, bound) if math.isfinite(bound) and bound > 0 else None
    density = ndimage.uniform_filter(np.asarray(dwell_s, dtype=np.float64), size=max(1, step_px), mode="constant")
    floor = 1e-9 * float(density.max(initial=0.0))  # the running-sum filter leaves ~1e-17 where no dwell is
    dwell = np.where(density > floor, density / pixel_mm**2, np.nan)  # s per mm^2 of the part
    figure = new_figure(11, 9)
    grid = figure.subplots(2, 2)
    _panel(figure, grid[0, 0], measured_nm, extent, f"measured surface before (nm): {_stats(measured_nm)}",
           "surface, nm", None, SIGNED_CMAP)
    _panel(figure, grid[0, 1], dwell, extent, f"dwell density (s/mm^2): total {row.total_dwell_s:.0f} s, "
           f"{row.points} points", "dwell, s/mm^2", None, "viridis")
    _panel(figure, grid[1, 0], predicted_residual_nm, extent,
           f"predicted residual (nm): {_stats(np.asarray(predicted_residual_nm))}", "surface, nm", shared,
           SIGNED_CMAP)
    _panel(figure, grid[1, 1], after, extent, f"measured residual (nm): {_stats(after)}", "surface, nm", shared,
           SIGNED_CMAP)
    figure.suptitle(f"run {row.run}, job {row.job_id}: {row.rms_before_nm:.2f} nm RMS before, "
                    f"{row.predicted_rms_nm:.2f} predicted, "
                    + (f"{row.measured_rms_nm:.2f} measured" if math.isfinite(row.measured_rms_nm) else "not measured"))
    path = Path(folder) / run_plot_name(row.run)
    return save_figure(figure, path)
