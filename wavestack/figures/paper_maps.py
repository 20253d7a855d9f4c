"""The seed paper's pictures of one aperture, from ``bench paper``'s kept views (Figs. 3, 5 and 7).

* :func:`mesh_figure` (Fig. 3): each mapped method's mesh on the aperture (top) and its canonical
  image (bottom), every triangle coloured by ``log10`` of its normalised area scale ``s`` (0: the
  mesh's mean scale; one symmetric scale shared by all panels, so crowding reads the same colour
  for every method).
* :func:`beltrami_figure` (Fig. 5): ``|mu|`` per triangle on the aperture (top, scale 0 to 1: a
  diffeomorphism keeps ``|mu| < 1``) and its histogram (bottom).
* :func:`error_figure` (Fig. 7): the truth, then every method's fit error, the errors on one
  shared symmetric scale.

Physical coordinates are the mesh's pixels (x = column, y = -row, so the aperture stands as on
its mask); canonical ones are the unit disk's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from numpy.typing import NDArray

from wavestack.figures.paper_views import PaperViews
from wavestack.figures.drawing import BAR_COLOUR, MAGNITUDE_CMAP, SIGNED_CMAP, aperture_outline, map_panel
from wavestack.figures.drawing import mesh_panel, new_figure, symmetric_limits

__all__ = ["AREA_SCALE_FLOOR", "BELTRAMI_BINS", "beltrami_figure", "error_figure", "log_area_scale",
           "mesh_figure", "mesh_limits"]

#: Area scales below this (and flipped triangles, s <= 0) are drawn at it: log10 needs s > 0.
AREA_SCALE_FLOOR = 1e-3
#: Bin edges of the |mu| histograms: 40 bins over [0, 1].
BELTRAMI_BINS = np.linspace(0.0, 1.0, 41)
_PHYSICAL = ("x, px", "y, px")
_CANONICAL = ("u (canonical, unit radius)", "v (canonical, unit radius)")


def _mapped(views: Sequence[PaperViews]) -> list[PaperViews]:
    return [v for v in views if v.mapping is not None]


def log_area_scale(view: PaperViews) -> NDArray[np.float64]:
    """``log10`` of the triangles' normalised area scale, floored at :data:`AREA_SCALE_FLOOR`."""
    if view.mapping is None:
        raise ValueError(f"{view.aperture}, {view.label}: expected a mapped method (it has no mesh)")
    return np.log10(np.maximum(view.mapping.area_scale, AREA_SCALE_FLOOR))


def mesh_limits(views: Sequence[PaperViews]) -> tuple[float, float]:
    """The colour limits of :func:`mesh_figure`: symmetric over every mapped view's log10 area scale."""
    return symmetric_limits(*(log_area_scale(v) for v in _mapped(views)))


def _two_rows(views: Sequence[PaperViews], what: str) -> tuple[list[PaperViews], Figure, list[tuple[Axes, Axes]]]:
    """The mapped views, and a figure with a top and a bottom panel for each, made before any colour
    bar so that ``figure.axes`` starts with them in that order.

    Raises
    ------
    ValueError
        If no view has a canonical map.
    """
    mapped = _mapped(views)
    if not mapped:
        raise ValueError(f"{what}: expected at least one mapped method (conformal or csf-qcm)")
    figure = new_figure(3.8 * len(mapped), 7.0)
    grid = figure.add_gridspec(2, len(mapped))
    return mapped, figure, [(figure.add_subplot(grid[0, k]), figure.add_subplot(grid[1, k]))
                            for k in range(len(mapped))]


def mesh_figure(views: Sequence[PaperViews]) -> Figure:
    """Fig. 3 of the seed paper for one aperture: meshes and their canonical images.

    ``figure.axes`` starts with, per mapped method, the physical panel then the canonical one.
    A ValueError if no view has a canonical map.
    """
    mapped, figure, panels = _two_rows(views, "mesh figure")
    norm = Normalize(*mesh_limits(mapped))
    unit = "log10 area scale s (0: mean scale)"
    for (top, bottom), view in zip(panels, mapped):
        m = view.mapping
        spread = np.percentile(m.area_scale, 95) / max(np.percentile(m.area_scale, 5), AREA_SCALE_FLOOR)
        values = log_area_scale(view)
        mesh_panel(figure, top, m.vertices, m.triangles, values, norm=norm,
                   cmap=SIGNED_CMAP, title=f"{view.label}: mesh, s95/s5 {spread:.3g}", unit=unit,
                   axis_labels=_PHYSICAL)
        mesh_panel(figure, bottom, m.canonical, m.triangles, values, norm=norm,
                   cmap=SIGNED_CMAP, title=f"{view.label}: image"
                   + ("" if m.r_in is None else f", r_in = {m.r_in:.3f}"), unit=unit, axis_labels=_CANONICAL)
    figure.suptitle(f"{mapped[0].aperture}: meshes (top) and their canonical images (bottom), "
                    f"{len(mapped[0].mapping.triangles)} triangles")
    return figure


def beltrami_figure(views: Sequence[PaperViews]) -> Figure:
    """Fig. 5 of the seed paper for one aperture: ``|mu|`` maps (top) and histograms (bottom).

    ``figure.axes`` starts with, per mapped method, the map then the histogram. A ValueError if
    no view has a canonical map.
    """
    mapped, figure, panels = _two_rows(views, "Beltrami figure")
    for (top, histogram), view in zip(panels, mapped):
        m = view.mapping
        mesh_panel(figure, top, m.vertices, m.triangles, m.beltrami,
                   norm=Normalize(0.0, 1.0), cmap=MAGNITUDE_CMAP, edges=False,
                   title=f"{view.label}: |mu|, max {np.max(m.beltrami):.3f}", unit="|mu| (dimensionless)",
                   axis_labels=_PHYSICAL)
        histogram.hist(np.clip(m.beltrami, 0.0, 1.0), bins=BELTRAMI_BINS, color=BAR_COLOUR)
        histogram.set_title(f"{view.label}: p95 {np.percentile(m.beltrami, 95):.3f}", fontsize=8)
        histogram.set_xlabel("|mu| (dimensionless; > 1 clipped to 1)")
        histogram.set_ylabel("triangles")
        histogram.set_xlim(0.0, 1.0)
    figure.suptitle(f"{mapped[0].aperture}: Beltrami coefficient |mu| of each map")
    return figure


def _window(mask: NDArray[np.bool_], margin: int = 2) -> tuple[tuple[slice, slice], tuple[float, float, float, float]]:
    """The aperture's bounding box (plus ``margin`` pixels) and its extent in pixel coordinates."""
    rows, cols = np.nonzero(mask)
    r0, c0 = max(int(rows.min()) - margin, 0), max(int(cols.min()) - margin, 0)
    r1, c1 = min(int(rows.max()) + margin, mask.shape[0] - 1), min(int(cols.max()) + margin, mask.shape[1] - 1)
    return (slice(r0, r1 + 1), slice(c0, c1 + 1)), (c0 - 0.5, c1 + 0.5, r1 + 0.5, r0 - 0.5)


def error_figure(views: Sequence[PaperViews]) -> Figure:
    """Fig. 7 of the seed paper for one aperture: the truth, then each method's fit error.

    ``figure.axes[0]`` is the truth, ``figure.axes[1 + k]`` the error of ``views[k]``; the errors
    share :func:`~wavestack.figures.drawing.symmetric_limits` of all of them. The maps are cut to
    the aperture's bounding box; data coordinates stay the full grid's (x = column, y = row).
    """
    if not views:
        raise ValueError("error figure: expected at least one method")
    figure = new_figure(3.6 * (len(views) + 1), 3.8)
    panels = figure.subplots(1, len(views) + 1)
    window, extent = _window(views[0].mask)
    truth = views[0].truth
    shared = symmetric_limits(*(v.error for v in views))
    map_panel(figure, panels[0], truth[window], title=f"truth, PV {np.nanmax(truth) - np.nanmin(truth):.3g} waves",
              unit="wavefront, waves", extent=extent)
    aperture_outline(panels[0], views[0].mask[window], extent)
    for axes, view in zip(panels[1:], views):
        rms = float(np.sqrt(np.nanmean(np.asarray(view.error, dtype=np.float64) ** 2)))
        map_panel(figure, axes, view.error[window], title=f"{view.label}: error, RMS {rms:.2e}",
                  unit="error, waves", limits=shared, extent=extent)
        aperture_outline(axes, view.mask[window], extent)
    figure.suptitle(f"{views[0].aperture}: fit error (reconstruction minus truth, waves) of each method, one scale")
    return figure
