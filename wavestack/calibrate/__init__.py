"""Calibrating the instrument against its own reference: absolute tests through the running station.

:func:`calibrate_rotation` turns the part on a PI rotation stage, measures it at N positions through
the station service's maps and separates the part's non-symmetric figure from the reference's
(:mod:`wavestack.calibrate.rotation`); :func:`calibrate_reference` is the random ball test
(:mod:`wavestack.calibrate.ball`); both share :mod:`wavestack.calibrate.measure`. An application beside ``polish``, ``align`` and ``batch``: it
uses the station service and the pipeline, and none of them.
"""

from __future__ import annotations

from .ball import BallCalibration, BallTestSettings, ball_reference, calibrate_reference
from .measure import CalibrationFailed
from .rotation import (
    PositionRecord,
    RotationCalibration,
    RotationSettings,
    calibrate_rotation,
    reference_calibration,
)

__all__ = ["BallCalibration", "BallTestSettings", "CalibrationFailed", "PositionRecord", "RotationCalibration",
           "RotationSettings", "ball_reference", "calibrate_reference", "calibrate_rotation", "reference_calibration"]
