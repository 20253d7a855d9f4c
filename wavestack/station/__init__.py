"""The live station and the service the loops stand on: sources, devices, the result loop, outputs, sinks.

A cycle runs one way, one value per arrow: frames -> a processor's frozen outcome (the
pipeline's :class:`~wavestack.pipeline.instrument.InterferometerOutcome` or
:class:`~wavestack.pipeline.instrument.SlopeOutcome`) -> :func:`make_result` (pure) -> the
output stage (the PLC), which returns an :class:`OutputRecord` -> one
:class:`CycleRecord` for every sink.

The service the applications (``polish``, ``align``, ``batch``) use: :class:`StationService`
(the station on its own thread, its records to every sink), its averaged maps
(:class:`LiveMaps`: N valid maps in a row, or :class:`UntrustedMeasurement`), the PLC's status
(:class:`Heartbeat`), the result values and the processors.
"""

from __future__ import annotations

from wavestack.station.counters import Counters, FrameCounts, SetCounts
from wavestack.station.cycle import CycleRecord, ProcessorOutcome, ResultSink, make_result, with_output
from wavestack.station.devices import StationDevices, configure_camera, open_station_devices, phase_steps_rad
from wavestack.station.fitter_cache import FALLBACK_METHOD, FitterCache, FitterChoice
from wavestack.station.live_maps import LiveMaps, MapSample, UntrustedMeasurement, sample_of
from wavestack.station.live_view import LiveSnapshot, LiveStats, counter_lines, render_live_view
from wavestack.station.outputs import PlcOutput, start_up_hold
from wavestack.station.plc_status import Heartbeat
from wavestack.station.results import (
    ApertureRecord,
    FitDiagnostics,
    FitterDiagnostics,
    OutputRecord,
    ReconstructorDiagnostics,
    SentCommand,
    StationResult,
    TruthErrors,
    json_ready,
)
from wavestack.station.sources import CarrierSource, PhaseStepSource
from wavestack.station.service import StationService
from wavestack.station.station import Station, StationSummary, build_processor, interferometer_settings
from wavestack.station.truth import TruthCheck, coefficient_errors

__all__ = [
    "ApertureRecord",
    "CarrierSource", "Counters", "CycleRecord", "FALLBACK_METHOD", "FitDiagnostics", "FitterCache",
    "FitterChoice", "FitterDiagnostics", "FrameCounts", "Heartbeat", "LiveMaps",
    "LiveSnapshot", "LiveStats", "MapSample", "OutputRecord", "PhaseStepSource", "PlcOutput", "ProcessorOutcome",
    "ReconstructorDiagnostics", "ResultSink", "SentCommand", "SetCounts",
    "Station", "StationDevices", "StationResult", "StationService", "StationSummary", "TruthCheck",
    "TruthErrors", "UntrustedMeasurement", "build_processor", "coefficient_errors", "configure_camera",
    "counter_lines", "interferometer_settings", "json_ready", "make_result", "open_station_devices",
    "phase_steps_rad", "render_live_view", "sample_of",
    "start_up_hold", "with_output",
]
