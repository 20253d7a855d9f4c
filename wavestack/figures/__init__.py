"""Pictures of every measurement: the fit of one map, the seed paper's figures, a recording over time.

matplotlib's non-interactive Agg backend through the object API (nothing global is set). Every
figure has a title, axis labels with units, and a colour bar with its unit where it shows a map;
every builder returns the ``Figure`` (so a test can read its axes back) and a ``write_*`` function
saves it as a PNG of exactly ``inches * DPI`` pixels.

* one fit (``analyze --plot``, ``fit --plot``): :class:`FitView`, :func:`fit_figure`;
* the seed paper's figures (``bench paper --plots``): the views ``bench paper`` keeps
  (:class:`PaperViews`, :func:`paper_views`), :func:`write_paper_figures` and the figure
  builders :func:`mesh_figure`, :func:`ecdf_figure`, :func:`beltrami_figure`, :func:`gram_figure`,
  :func:`error_figure`;
* a replayed recording (``replay --plots``): :class:`ReplayCollector`, :class:`ReplaySeries`,
  :func:`write_replay_figures`;
* a polishing run (``polish --plots``): :func:`plot_run`;
* the common drawing: :func:`map_panel`, :func:`mesh_panel`, :func:`aperture_outline`,
  :func:`coefficient_bars`, :func:`mode_label`.
"""

from __future__ import annotations

from wavestack.figures.drawing import (
    BAR_COLOUR,
    DPI,
    MAGNITUDE_CMAP,
    MAX_BARS,
    SIGNED_CMAP,
    aperture_outline,
    coefficient_bars,
    data_limits,
    map_panel,
    mesh_panel,
    mode_label,
    new_figure,
    pixel_extent,
    save_figure,
    symmetric_limits,
)
from wavestack.figures.fit_figure import FIT_FIGURE_INCHES, FitView, fit_figure, write_fit_figure
from wavestack.figures.paper_figures import write_paper_figures
from wavestack.figures.paper_maps import AREA_SCALE_FLOOR, BELTRAMI_BINS, beltrami_figure, error_figure
from wavestack.figures.paper_maps import log_area_scale, mesh_figure, mesh_limits
from wavestack.figures.paper_views import MapView, PaperViews, paper_views
from wavestack.figures.paper_stats import GRAM_FLOOR, ecdf, ecdf_figure, gram_figure, gram_norm
from wavestack.figures.polish_run import plot_run, run_plot_name
from wavestack.figures.replay_figures import LEADING_MODES, ReplayCollector, ReplaySeries, coefficient_figure
from wavestack.figures.replay_figures import last_map_figure, latency_figure, write_replay_figures

__all__ = [
    "AREA_SCALE_FLOOR", "BAR_COLOUR", "BELTRAMI_BINS", "DPI", "FIT_FIGURE_INCHES", "FitView", "GRAM_FLOOR",
    "LEADING_MODES", "MAGNITUDE_CMAP", "MAX_BARS", "MapView", "PaperViews", "ReplayCollector", "ReplaySeries", "SIGNED_CMAP",
    "aperture_outline", "beltrami_figure", "coefficient_bars", "coefficient_figure", "data_limits", "ecdf",
    "ecdf_figure", "error_figure", "fit_figure", "gram_figure", "gram_norm", "last_map_figure", "latency_figure",
    "log_area_scale", "map_panel", "mesh_figure", "mesh_limits", "mesh_panel", "mode_label", "new_figure", "paper_views",
    "pixel_extent", "plot_run", "run_plot_name", "save_figure", "symmetric_limits", "write_fit_figure", "write_paper_figures",
    "write_replay_figures",
]
