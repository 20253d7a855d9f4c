"""The figure of one fit (``wavestack analyze --plot``, ``wavestack fit --plot``).

Four panels: the measured map, the fitted map, the residual (measured minus fitted) and the
coefficients as named bars; below them, when the command measured them, the surface figures'
PSD, slope and filtered panels (:mod:`wavestack.figures.surface_panels`). The measured and fitted maps share one colour scale, so their colours
compare directly; the residual, usually far smaller, gets its own symmetric scale (on the shared
one it would be a uniform white).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from wavestack.figures.drawing import aperture_outline, coefficient_bars, map_panel, new_figure, save_figure
from wavestack.figures.drawing import symmetric_limits
from wavestack.figures.surface_panels import draw_surface_panels, surface_panel_count
from wavestack.pipeline import SurfaceFigures

__all__ = ["FIT_FIGURE_INCHES", "FitView", "fit_figure", "write_fit_figure"]

#: Size of the fit figure, inches (width, height).
FIT_FIGURE_INCHES = (15.0, 9.0)


@dataclass(frozen=True, eq=False)
class FitView:
    """What the fit figure shows.

    Attributes
    ----------
    measured : ndarray, shape (H, W)
        The map that was fitted (less any removed piston and tilt), NaN outside the aperture.
    fitted : ndarray, shape (H, W)
        The fitted map, NaN outside the fitted pixels.
    residual : ndarray, shape (H, W)
        ``measured - fitted``, NaN outside.
    coefficients : ndarray, shape (M,)
    modes : tuple of (n, m)
    first_index : int
        Index of the first mode in the ordering (1 for Noll).
    unit : str
        Unit of the maps and coefficients ("waves", "nm", "map units").
    source : str
        What was fitted (a file name), for the title.
    method : str
        The fit method.
    removed : str or None
        "ptt" or "pttp" when those terms were removed before the fit.
    surface : SurfaceFigures or None
        The surface figures; their PSD, slope and filtered surface get panels of their own.
    """

    measured: NDArray[np.float64]
    fitted: NDArray[np.float64]
    residual: NDArray[np.float64]
    coefficients: NDArray[np.float64]
    modes: tuple[tuple[int, int], ...]
    first_index: int
    unit: str
    source: str
    method: str
    removed: str | None = None
    surface: SurfaceFigures | None = None


def _stats(values: NDArray[np.float64], unit: str) -> str:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return "no valid pixel"
    return f"RMS {np.std(finite):.4g}, PV {np.ptp(finite):.4g} {unit}"


def fit_figure(view: FitView) -> Figure:
    """The fit's figure: measured, fitted and residual maps over the coefficient bars.

    ``figure.axes[:3]`` are the measured, fitted and residual maps, ``figure.axes[3]`` the bars
    (the colour bars follow). Measured and fitted use :func:`~wavestack.figures.drawing.symmetric_limits` of both,
    the residual its own.

    Example
    -------
    >>> rows, cols = np.indices((16, 16))
    >>> inside = np.hypot(rows - 7.5, cols - 7.5) < 7
    >>> fitted = np.where(inside, (cols - 7.5) / 8.0, np.nan)
    >>> view = FitView(fitted + 0.01, fitted, np.where(inside, 0.01, np.nan), np.array([0.01, 1.0]),
    ...                ((0, 0), (1, 1)), 1, "waves", "example", "circle")
    >>> [a.get_title()[:8] for a in fit_figure(view).axes[:3]]
    ['measured', 'fitted (', 'residual']
    """
    extra = surface_panel_count(view.surface)
    width, height = FIT_FIGURE_INCHES
    figure = new_figure(width, height + (4.5 if extra else 0.0))
    grid = figure.add_gridspec(3 if extra else 2, 3, height_ratios=(1.15, 1.0, 1.15)[: 3 if extra else 2])
    maps = [figure.add_subplot(grid[0, k]) for k in range(3)]
    bars = figure.add_subplot(grid[1, :])
    shared = symmetric_limits(view.measured, view.fitted)
    mask = np.isfinite(view.measured)
    removed = {"ptt": ", piston and tilt removed", "pttp": ", piston, tilt and power removed"}.get(view.removed or "", "")
    label = f"wavefront, {view.unit}"
    panels = (
        (view.measured, f"measured{removed}\n{_stats(view.measured, view.unit)}", shared, label),
        (view.fitted, f"fitted ({view.method}, {len(view.modes)} modes)\n{_stats(view.fitted, view.unit)}", shared,
         label),
        (view.residual, f"residual (measured - fitted)\n{_stats(view.residual, view.unit)}",
         symmetric_limits(view.residual), f"residual, {view.unit}"),
    )
    for axes, (data, title, limits, unit) in zip(maps, panels):
        map_panel(figure, axes, data, title=title, unit=unit, limits=limits)
        aperture_outline(axes, mask)
    coefficient_bars(bars, view.coefficients, view.modes, view.first_index, unit=view.unit,
                     title=f"coefficients ({view.unit})")
    if extra:
        draw_surface_panels(figure, [figure.add_subplot(grid[2, k]) for k in range(extra)], view.surface)
    rms = float(np.nanstd(view.residual)) if np.isfinite(view.residual).any() else math.nan
    figure.suptitle(f"{view.source}: {view.method} fit of {len(view.modes)} modes, residual RMS {rms:.4g} {view.unit}")
    return figure


def write_fit_figure(view: FitView, path: str | Path) -> Path:
    """Draw :func:`fit_figure` and write it to ``path`` (PNG); returns the path."""
    return save_figure(fit_figure(view), path)
