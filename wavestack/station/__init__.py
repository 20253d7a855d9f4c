"""The live station: sources, devices, the two processors, the one-way result loop, outputs, live view.

A cycle runs one way, one value per arrow: frames -> a processor's frozen outcome (the
pipeline's :class:`~wavestack.pipeline.instrument.InterferometerOutcome` or
:class:`~wavestack.pipeline.instrument.SlopeOutcome`) -> :func:`make_result` (pure) -> the
output stage (safety stage, PLC), which returns an :class:`OutputRecord` -> one
:class:`CycleRecord` for every sink.
"""

from __future__ import annotations

from wavestack.station.counters import Counters, FrameCounts, SetCounts
from wavestack.station.cycle import CycleRecord, ProcessorOutcome, ResultSink, make_result, with_output
from wavestack.station.devices import StationDevices, configure_camera, open_station_devices, phase_steps_rad
from wavestack.station.fitter_cache import FALLBACK_METHOD, FitterCache, FitterChoice
from wavestack.station.live_view import LiveSnapshot, LiveStats, counter_lines, render_live_view
from wavestack.station.outputs import PlcOutput, start_up_hold
from wavestack.station.results import (
    ApertureRecord,
    FitDiagnostics,
    FitterDiagnostics,
    Heartbeat,
    OutputRecord,
    ReconstructorDiagnostics,
    SentCommand,
    StationResult,
    TruthErrors,
    json_ready,
)
from wavestack.station.set_batch import GROUP_SETS, SetBatch
from wavestack.station.sources import CarrierSource, PhaseStepSource
from wavestack.station.station import Station, StationSummary, build_processor, interferometer_settings
from wavestack.station.truth import TruthCheck, coefficient_errors

__all__ = [
    "ApertureRecord",
    "CarrierSource", "Counters", "CycleRecord", "FALLBACK_METHOD", "FitDiagnostics", "FitterCache",
    "FitterChoice", "FitterDiagnostics", "FrameCounts", "GROUP_SETS", "Heartbeat",
    "LiveSnapshot", "LiveStats", "OutputRecord", "PhaseStepSource", "PlcOutput", "ProcessorOutcome",
    "ReconstructorDiagnostics", "ResultSink", "SentCommand", "SetBatch", "SetCounts",
    "Station", "StationDevices", "StationResult", "StationSummary", "TruthCheck",
    "TruthErrors", "build_processor", "coefficient_errors", "configure_camera", "counter_lines", "interferometer_settings",
    "json_ready", "make_result", "open_station_devices", "phase_steps_rad", "render_live_view",
    "start_up_hold", "with_output",
]
