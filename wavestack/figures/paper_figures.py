"""``wavestack bench paper --plots DIR``: every seed-paper figure of a benchmark run, one PNG each."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from wavestack.figures.paper_views import PaperViews
from wavestack.figures.drawing import save_figure
from wavestack.figures.paper_maps import beltrami_figure, error_figure, mesh_figure
from wavestack.figures.paper_stats import ecdf_figure, gram_figure

__all__ = ["write_paper_figures"]

logger = logging.getLogger(__name__)


def write_paper_figures(views: Sequence[PaperViews], folder: str | Path) -> list[Path]:
    """Write the seed paper's figures rebuilt from ``views`` into ``folder``; returns the paths.

    Per aperture: ``meshes-NAME.png`` (Fig. 3), ``beltrami-NAME.png`` (Fig. 5; these two only when
    a mapped method ran), ``gram-NAME.png`` (Fig. 6), ``errors-NAME.png`` (Fig. 7); and once
    ``area-scale-ecdf.png`` (Fig. 4).

    Parameters
    ----------
    views : sequence of PaperViews
        In table order (``run_paper_cases(..., keep_views=True)``).
    folder : str or Path
        An existing, writable folder.
    """
    target = Path(folder)
    paths = []
    apertures = list(dict.fromkeys(v.aperture for v in views))
    mapped = [v for v in views if v.mapping is not None]
    for name in apertures:
        mine = [v for v in views if v.aperture == name]
        drawers = [("gram", gram_figure), ("errors", error_figure)]
        if any(v.mapping is not None for v in mine):
            drawers = [("meshes", mesh_figure), ("beltrami", beltrami_figure), *drawers]
        for stem, draw in drawers:
            paths.append(save_figure(draw(mine), target / f"{stem}-{name}.png"))
            logger.info("wrote %s", paths[-1])
    if mapped:
        paths.append(save_figure(ecdf_figure(mapped), target / "area-scale-ecdf.png"))
    return paths
