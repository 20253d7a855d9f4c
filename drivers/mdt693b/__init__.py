"""Thorlabs MDT693B (3-axis) / MDT694B (1-axis) open-loop piezo controller.

``protocol`` encodes and parses the ASCII protocol (pure, fuzzable), ``command_sets`` holds the
controller's own command set and the older MDT693A one (its compatibility mode; an MDT693A speaks
only that) as data, ``limits`` combines the software, device and limit-switch voltage ranges (pure),
``driver`` runs the command exchanges on the one byte link (:mod:`wavestack.drivers.link`) and knows what to ask
(:class:`MDT693B`), ``phase_stepping`` sequences piezo steps with camera frames for
phase-shifting interferometry.
"""

from __future__ import annotations

from wavestack.drivers.mdt693b.command_sets import A_COMMANDS, B_COMMANDS, CommandSet
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
    "A_COMMANDS",
    "B_COMMANDS",
    "MDT693B",
    "CommandSet",
    "AxisLimits",
    "DeviceIdentity",
    "PhaseShifter",
    "PhaseStepCalibration",
    "Reply",
    "TriggeredFrameSource",
    "VoltageReading",
    "acquire_phase_steps",
]
