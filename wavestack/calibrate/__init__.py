"""Calibrating the instrument against its own reference: the rotation test through the running station.

:func:`calibrate_rotation` turns the part on a PI rotation stage, measures it at N positions through
the station service's maps and separates the part's non-symmetric figure from the reference's
(:mod:`wavestack.calibrate.rotation`). An application beside ``polish``, ``align`` and ``batch``: it
uses the station service and the pipeline, and none of them.
"""

from __future__ import annotations

from .rotation import (
    CalibrationFailed,
    PositionRecord,
    RotationCalibration,
    RotationSettings,
    calibrate_rotation,
    reference_calibration,
)

__all__ = ["CalibrationFailed", "PositionRecord", "RotationCalibration", "RotationSettings", "calibrate_rotation",
           "reference_calibration"]
