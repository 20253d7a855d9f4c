"""Instruments: one processor per instrument kind, from frames to a frozen outcome.

Above ``fit``: a processor strings phase, aperture, unwrapping, the data-quality mask, the fit,
spike clipping and the map's figures (PV, PVr) together, with its state explicit, and knows nothing
of devices, threads or the PLC. Every command calls it: the station (live), ``replay``, ``batch``,
``polish``, ``align``, and ``analyze`` (a stream of one set, :func:`measure_set`).

* processors: :class:`PhaseShiftingProcessor`, :class:`CarrierProcessor` (:func:`processor_for`);
* what they are told: :class:`InterferometerSettings`, :class:`QualitySettings`, :class:`FitSettings`;
* where their fitters come from: the :class:`FitterSource` protocol, :class:`SyncFitterSource`;
* what they return: :class:`InterferometerOutcome` with :class:`PixelQuality` and :class:`MapStatistics`;
* shared by every instrument (a Shack-Hartmann processor too): the aperture confirmation table
  (:func:`confirm`), the fitter source, :class:`InstrumentOutcome`, :class:`ApertureRecord`,
  :class:`FitDiagnostics`, :class:`PixelQuality`, :class:`MapStatistics`.
"""

from __future__ import annotations

from .carrier import CarrierProcessor
from .confirmation import (
    IMPOSSIBLE,
    TRANSITIONS,
    ApertureAction,
    ApertureEvent,
    AperturePhase,
    ApertureState,
    Detection,
    confirm,
)
from .fitter_source import (
    FALLBACK_METHOD,
    FitSettings,
    FitterChoice,
    FitterSource,
    SyncFitterSource,
    build_configured,
    choice_of,
)
from .interferometer import InterferometerProcessor, PhaseMaps, PreparedSet
from .outcome import ApertureRecord, FitDiagnostics, InstrumentOutcome, InterferometerOutcome
from .phase_shifting import PhaseShiftingProcessor
from .quality import (
    CLIPPED,
    LOW_MODULATION,
    OUTSIDE,
    RIM,
    SATURATED,
    UNTRUSTED_ORDER,
    PixelQuality,
    QualityMask,
    full_scale_of,
    mark_quality,
)
from .settings import ConicNull, InterferometerSettings, QualitySettings
from .statistics import MAX_CLIP_PASSES, PVR_MODES, MapStatistics, clip_spikes, map_pv, pvr_fitter, robust_pv
from .streams import measure_map, measure_set, processor_for
from .tracking import AdoptedAperture, ApertureConfirming, ApertureKeeper

__all__ = [
    "CLIPPED",
    "FALLBACK_METHOD",
    "IMPOSSIBLE",
    "LOW_MODULATION",
    "MAX_CLIP_PASSES",
    "OUTSIDE",
    "PVR_MODES",
    "RIM",
    "SATURATED",
    "TRANSITIONS",
    "UNTRUSTED_ORDER",
    "AdoptedAperture",
    "ApertureAction",
    "ApertureEvent",
    "ApertureConfirming",
    "ApertureKeeper",
    "AperturePhase",
    "ApertureRecord",
    "ApertureState",
    "CarrierProcessor",
    "ConicNull",
    "Detection",
    "FitDiagnostics",
    "FitSettings",
    "FitterChoice",
    "FitterSource",
    "InstrumentOutcome",
    "InterferometerOutcome",
    "InterferometerProcessor",
    "InterferometerSettings",
    "MapStatistics",
    "PhaseMaps",
    "PhaseShiftingProcessor",
    "PixelQuality",
    "PreparedSet",
    "QualityMask",
    "QualitySettings",
    "SyncFitterSource",
    "build_configured",
    "choice_of",
    "clip_spikes",
    "confirm",
    "full_scale_of",
    "map_pv",
    "mark_quality",
    "measure_map",
    "measure_set",
    "processor_for",
    "pvr_fitter",
    "robust_pv",
]
