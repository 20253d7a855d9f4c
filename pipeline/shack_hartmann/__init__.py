"""Shack-Hartmann: lenslet grid, spot centroids, slopes, modal and zonal wavefront reconstruction."""

from __future__ import annotations

from .centroids import (
    Centroider,
    LensletGrid,
    SlopeResult,
    SpotMeasurement,
    centroid_spots,
    convert_slopes,
    detect_grid,
    slopes,
    slopes_in_waves_per_radius,
)
from .modal import ModalReconstructor, SouthwellReconstructor, southwell_reconstruct

__all__ = [
    "Centroider",
    "LensletGrid",
    "ModalReconstructor",
    "SlopeResult",
    "SouthwellReconstructor",
    "SpotMeasurement",
    "centroid_spots",
    "convert_slopes",
    "detect_grid",
    "slopes",
    "slopes_in_waves_per_radius",
    "southwell_reconstruct",
]
