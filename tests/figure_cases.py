"""Small seed-paper views for the figure tests: one aperture, coarse meshes, few modes (seconds, not minutes)."""

from __future__ import annotations

import numpy as np

from wavestack.bench import PAPER_APERTURES
from wavestack.figures.paper_views import PaperViews
from wavestack.figures.paper_views import paper_views
from wavestack.pipeline import Aperture, build_fitter

NAME = "annulus-circular-hole"
METHODS = (("circle", "circle", {}), ("conformal", "conformal", {}),
           ("csf-qcm", "csf-qcm (cotangent, balanced)", {"angular_balance": True}))


def small_views(size: int = 40, vertices: int = 120, modes: int = 10) -> list[PaperViews]:
    """The views of three methods on a small annulus, built as ``bench paper`` builds them."""
    aperture = Aperture.from_mask(PAPER_APERTURES[NAME](size))
    rows, cols = np.nonzero(aperture.mask)
    truth = 0.02 * np.sin(cols / 5.0) + 0.01 * np.cos(rows / 4.0)
    views = []
    for method, label, options in METHODS:
        fitter = build_fitter(aperture, method=method, modes=modes, dtype=np.float64, mesh_vertices=vertices,
                              **options)
        frame = np.full(aperture.shape, np.nan)
        frame[rows, cols] = truth
        fitted = fitter.surface(fitter.fit(frame).coefficients)[rows, cols]
        views.append(paper_views(NAME, label, aperture, fitter, truth, fitted))
    return views
