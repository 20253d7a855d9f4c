"""Benchmarks that print figures (``wavestack bench``): the seed paper's tables and the simulated station.

The paper's apertures (:mod:`~wavestack.bench.paper_apertures`) live here too; the bundled
example and the numerical benchmarks use them.
"""

from __future__ import annotations

from wavestack.bench.paper import PaperCase, PaperRow, format_markdown, rows_as_json, run_paper_benchmark, run_paper_cases
from wavestack.bench.paper_apertures import (
    PAPER_APERTURES,
    annulus_circular_hole_mask,
    annulus_triangular_hole_mask,
    butterfly_mask,
    rectangle_mask,
    rounded_rectangle_mask,
)
from wavestack.bench.station import carrier_config, changed_aperture, machine_state, measure_path
from wavestack.bench.station_figures import STAGES, MachineState, StationPathFigures, figures_json, format_figures, targets

__all__ = [
    "MachineState", "PAPER_APERTURES", "PaperCase", "PaperRow", "STAGES",
    "StationPathFigures", "annulus_circular_hole_mask",
    "annulus_triangular_hole_mask", "butterfly_mask", "carrier_config", "changed_aperture", "figures_json",
    "format_figures", "format_markdown", "machine_state", "measure_path", "rectangle_mask",
    "rounded_rectangle_mask", "rows_as_json", "run_paper_benchmark",
    "run_paper_cases", "targets",
]
