"""Instruments: one processor per instrument kind, from frames to a frozen outcome.

Above ``fit`` and ``shack_hartmann``: a processor turns one set of camera frames into one frozen
outcome (``process(frames) -> outcome``), keeping its state explicit and knowing nothing of devices,
threads or the PLC. Every command calls it: the station (live), ``replay``, ``batch``, ``polish``,
``align``, and ``analyze`` (a stream of one set), so the same frames give the same numbers whichever
command reads them.

* interferometers: :class:`PhaseShiftingProcessor`, :class:`CarrierProcessor` (:func:`processor_for`,
  :func:`measure_set`): phase, aperture, unwrapping, the data-quality mask, the fit, spike clipping
  and the map's figures (PV, PVr); told by :class:`InterferometerSettings`, :class:`QualitySettings`,
  :class:`FitSettings`; their fitters from the :class:`FitterSource` protocol
  (:class:`SyncFitterSource`); returning :class:`InterferometerOutcome`;
* Shack-Hartmann: :class:`ShackHartmannProcessor` (:mod:`.shack_hartmann`): spot frames to Zernike
  terms, on a square or hexagonal lenslet lattice (configured, or found in a reference frame),
  described by a :class:`ShackHartmannSetup` (:mod:`.sensor_setup`), its geometry built once per
  reference (:mod:`.lenslet_geometry`); returning :class:`SlopeOutcome`;
* shared by every instrument: the aperture confirmation table (:func:`confirm`),
  :class:`InstrumentOutcome`, the records an outcome carries (:mod:`.records`:
  :class:`ApertureRecord`, :class:`FitDiagnostics`, :class:`ReconstructorDiagnostics`),
  :class:`PixelQuality`, :class:`MapStatistics`.
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
from .lenslet_geometry import LensletGeometry, cells_inside, configured_lattice, lenslet_geometry
from .outcome import InstrumentOutcome, InterferometerOutcome
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
from .records import ApertureRecord, FitDiagnostics, ReconstructorDiagnostics
from .sensor_setup import ShackHartmannSetup
from .settings import ConicNull, InterferometerSettings, QualitySettings
from .shack_hartmann import (
    MODAL,
    LensletSlopes,
    ReconstructorCache,
    ShackHartmannProcessor,
    ShackHartmannState,
    SlopeOutcome,
)
from .statistics import MapStatistics, clip_spikes, map_pv, pvr_analyzer, robust_pv
from .streams import measure_map, measure_set, processor_for
from .tracking import AdoptedAperture, ApertureConfirming, ApertureKeeper, null_waves

__all__ = [
    "CLIPPED",
    "FALLBACK_METHOD",
    "IMPOSSIBLE",
    "LOW_MODULATION",
    "MODAL",
    "OUTSIDE",
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
    "LensletGeometry",
    "LensletSlopes",
    "MapStatistics",
    "PhaseMaps",
    "PhaseShiftingProcessor",
    "PixelQuality",
    "PreparedSet",
    "QualityMask",
    "QualitySettings",
    "ReconstructorCache",
    "ReconstructorDiagnostics",
    "ShackHartmannProcessor",
    "ShackHartmannSetup",
    "ShackHartmannState",
    "SlopeOutcome",
    "SyncFitterSource",
    "build_configured",
    "cells_inside",
    "choice_of",
    "clip_spikes",
    "configured_lattice",
    "confirm",
    "full_scale_of",
    "lenslet_geometry",
    "map_pv",
    "mark_quality",
    "measure_map",
    "measure_set",
    "null_waves",
    "processor_for",
    "pvr_analyzer",
    "robust_pv",
]
