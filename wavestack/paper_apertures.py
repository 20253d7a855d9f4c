"""Moved to :mod:`wavestack.bench.paper_apertures`; this name stays importable for the benchmarks and
the pipeline tests that use it (``from wavestack.bench import ...`` is the face to use)."""

from __future__ import annotations

from wavestack.bench.paper_apertures import (
    PAPER_APERTURES,
    SIZE,
    annulus_circular_hole_mask,
    annulus_triangular_hole_mask,
    butterfly_mask,
    rectangle_mask,
    rounded_rectangle_mask,
)

__all__ = ["PAPER_APERTURES", "SIZE", "annulus_circular_hole_mask", "annulus_triangular_hole_mask",
           "butterfly_mask", "rectangle_mask", "rounded_rectangle_mask"]
