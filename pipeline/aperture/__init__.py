"""Apertures: the valid region of a frame, its detection, comparison and tracking, and the per-frame
watch.
"""

from __future__ import annotations

from .compare import ApertureChange, ApertureTracker, aperture_iou, compare_apertures
from .detect import DetectedAperture, DetectionSettings, detect_aperture
from .region import Aperture, EmptyAperture, Topology, UnsupportedAperture
from .watch import ApertureWatch, WatchVerdict

__all__ = [
    "Aperture",
    "ApertureChange",
    "ApertureTracker",
    "ApertureWatch",
    "DetectedAperture",
    "DetectionSettings",
    "EmptyAperture",
    "Topology",
    "UnsupportedAperture",
    "WatchVerdict",
    "aperture_iou",
    "compare_apertures",
    "detect_aperture",
]
