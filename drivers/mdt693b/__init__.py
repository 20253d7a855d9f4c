"""Thorlabs MDT693B (3-axis) / MDT694B (1-axis) open-loop piezo controller.

``protocol`` encodes and parses the ASCII protocol (pure, fuzzable), ``limits`` combines the
software, device and limit-switch voltage ranges (pure), ``driver`` holds the serial connection
(:class:`MDT693B`), ``phase_stepping`` sequences piezo steps with camera frames for
phase-shifting interferometry.
"""

from __future__ import annotations

from wavestack.drivers.mdt693b.driver import MDT693B, VoltageReading
from wavestack.drivers.mdt693b.limits import AxisLimits
from wavestack.drivers.mdt693b.phase_stepping import (
    PhaseShifter,
    PhaseStepCalibration,
    TriggeredFrameSource,
    acquire_phase_steps,
)
from wavestack.drivers.mdt693b.protocol import DeviceIdentity, Reply

__all__ = [
    "MDT693B",
    "AxisLimits",
    "DeviceIdentity",
    "PhaseShifter",
    "PhaseStepCalibration",
    "Reply",
    "TriggeredFrameSource",
    "VoltageReading",
    "acquire_phase_steps",
]
