"""The seed paper's statistics figures, from ``bench paper``'s kept views (Figs. 4 and 6).

* :func:`ecdf_figure` (Fig. 4): per aperture, the empirical CDF of the normalised per-triangle
  area scale ``s`` of every mapped method, on a log axis (a steep curve near 1 is a uniform map).
* :func:`gram_figure` (Fig. 6): ``|G|`` of every method's basis on one aperture, on a log colour
  scale from :data:`GRAM_FLOOR` (so crosstalk of a percent shows, and the identity is the ideal).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from numpy.typing import NDArray

from wavestack.figures.paper_views import PaperViews
from wavestack.figures.drawing import MAGNITUDE_CMAP, new_figure

__all__ = ["GRAM_FLOOR", "ecdf", "ecdf_figure", "gram_figure", "gram_norm"]

#: Smallest |G_ij| the Gram figures resolve; smaller entries take the bottom colour.
GRAM_FLOOR = 1e-3


def ecdf(values: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The empirical CDF as steps: sorted values and the fraction of values at or below each.

    Example
    -------
    >>> ecdf(np.array([3.0, 1.0, 2.0, 2.0]))
    (array([1., 2., 2., 3.]), array([0.25, 0.5 , 0.75, 1.  ]))
    """
    ordered = np.sort(np.asarray(values, dtype=np.float64))
    return ordered, np.arange(1, ordered.size + 1) / ordered.size


def ecdf_figure(views: Sequence[PaperViews]) -> Figure:
    """Fig. 4 of the seed paper: one panel per aperture, one ECDF curve per mapped method.

    ``figure.axes[k]`` is the ``k``-th aperture in the order first met in ``views``; its lines
    are that aperture's mapped methods in order. Area scales <= 0 (flipped triangles) cannot be
    drawn on the log axis and are counted in the legend.

    Raises
    ------
    ValueError
        If no view has a canonical map.
    """
    mapped = [v for v in views if v.mapping is not None]
    if not mapped:
        raise ValueError("ECDF figure: expected at least one mapped method (conformal or csf-qcm)")
    apertures = list(dict.fromkeys(v.aperture for v in mapped))
    figure = new_figure(5.0 * len(apertures), 4.2)
    panels = np.atleast_1d(figure.subplots(1, len(apertures)))
    for axes, name in zip(panels, apertures):
        for view in (v for v in mapped if v.aperture == name):
            scale = view.mapping.area_scale
            flipped = int(np.count_nonzero(scale <= 0))
            x, y = ecdf(scale)
            axes.step(x[x > 0], y[x > 0], where="post", linewidth=1.4,
                      label=view.label + (f" ({flipped} flipped)" if flipped else ""))
        axes.set_xscale("log")
        axes.axvline(1.0, color="grey", linewidth=0.6, linestyle=":")
        axes.set_xlabel("normalised area scale s (1: uniform)")
        axes.set_ylabel("ECDF (fraction of triangles)")
        axes.set_ylim(0.0, 1.0)
        axes.set_title(f"{name}: area scale of each map", fontsize=9)
        axes.legend(fontsize=7, loc="upper left")
        axes.grid(linewidth=0.3)
    figure.suptitle("area scale s, ECDF (paper Fig. 4)")
    return figure


def gram_norm(views: Sequence[PaperViews]) -> LogNorm:
    """The colour scale of :func:`gram_figure`: log from :data:`GRAM_FLOOR` to the largest |G_ij| (at least 1)."""
    top = max(1.0, *(float(np.max(np.abs(v.gram))) for v in views))
    return LogNorm(GRAM_FLOOR, top, clip=True)


def gram_figure(views: Sequence[PaperViews]) -> Figure:
    """Fig. 6 of the seed paper for one aperture: ``|G|`` of each method's basis.

    Element ``(i, j)`` of ``views[k].gram`` is drawn at data point ``(j + 1, i + 1)`` of
    ``figure.axes[k]`` (modes counted from 1, Noll), coloured by :func:`gram_norm`.
    """
    if not views:
        raise ValueError("Gram figure: expected at least one method")
    figure = new_figure(4.0 * len(views), 4.0)
    panels = np.atleast_1d(figure.subplots(1, len(views)))
    norm = gram_norm(views)
    for axes, view in zip(panels, views):
        size = view.gram.shape[0]
        eigenvalues = np.linalg.eigvalsh(view.gram)
        kappa = eigenvalues[-1] / eigenvalues[0] if eigenvalues[0] > 0 else np.inf
        image = axes.imshow(np.abs(view.gram), norm=norm, cmap=MAGNITUDE_CMAP, interpolation="nearest",
                            extent=(0.5, size + 0.5, size + 0.5, 0.5))
        axes.set_title(f"{view.label}: kappa(G) = {kappa:.4g}", fontsize=8)
        axes.set_xlabel("mode j (Noll)")
        axes.set_ylabel("mode i (Noll)")
        figure.colorbar(image, ax=axes, label="|G_ij| (dimensionless)", shrink=0.8)
    figure.suptitle(f"{views[0].aperture}: Gram matrices G = H^T H / N, first {views[0].gram.shape[0]} modes "
                    "(paper Fig. 6; ideal: identity)")
    return figure
