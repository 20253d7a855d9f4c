"""Apertures: the valid region of a frame, its detection, comparison and tracking, and the per-frame
watch.
"""

from __future__ import annotations

from .choice import APERTURE_CHOICES, ChosenAperture, choose_aperture
from .compare import ApertureChange, ApertureTracker, aperture_iou, compare_apertures
from .detect import DetectedAperture, DetectionSettings, detect_aperture
from .edge_circle import EdgeCircle, EdgeFitError, edge_points, fit_circle, fit_edge_circle
from .levels import ModulationLevels, modulation_levels
from .region import Aperture, EmptyAperture, Topology, UnsupportedAperture
from .watch import ApertureWatch, WatchVerdict

__all__ = [
    "APERTURE_CHOICES",
    "Aperture",
    "ApertureChange",
    "ApertureTracker",
    "ApertureWatch",
    "ChosenAperture",
    "DetectedAperture",
    "DetectionSettings",
    "EdgeCircle",
    "EdgeFitError",
    "EmptyAperture",
    "ModulationLevels",
    "Topology",
    "UnsupportedAperture",
    "WatchVerdict",
    "aperture_iou",
    "choose_aperture",
    "compare_apertures",
    "detect_aperture",
    "edge_points",
    "fit_circle",
    "fit_edge_circle",
    "modulation_levels",
]
