"""One cycle of the station as values: a processor's outcome -> the result -> the record every sink gets.

:func:`make_result` is pure: it turns a processor's frozen outcome (an
:class:`~wavestack.pipeline.instrument.InterferometerOutcome` or a
:class:`~wavestack.pipeline.instrument.SlopeOutcome`, both seen through
:class:`ProcessorOutcome`) and the cycle's facts into a
:class:`~wavestack.station.results.StationResult`. The output stage then sends the result and
returns what it sent; the :class:`CycleRecord` holding both is what every sink receives.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.frames import Frame
from wavestack.station.counters import Counters
from wavestack.pipeline.instrument import InstrumentOutcome
from wavestack.station.results import (
    FitterDiagnostics,
    OutputRecord,
    StationResult,
    TruthErrors,
)
from wavestack.pipeline.instrument import LensletSlopes


class ProcessorOutcome(InstrumentOutcome, Protocol):
    """What every processor's outcome tells the result (read-only): the pipeline's
    :class:`~wavestack.pipeline.instrument.InstrumentOutcome` and the fitter's diagnostics."""

    @property
    def diagnostics(self) -> FitterDiagnostics | None: ...


def make_result(index: int, frames: tuple[Frame, ...], outcome: ProcessorOutcome, *, ordering: str,
                counters: Counters, now_ns: int, truth: TruthErrors | None = None) -> StationResult:
    """The result of one processed set (pure).

    Parameters
    ----------
    index : int
        Result number in this run.
    frames : tuple of Frame
        The set (non-empty); its first frame's host time is the exposure time.
    outcome : ProcessorOutcome
    ordering : str
        The coefficients' Zernike ordering.
    counters : Counters
    now_ns : int
        Host time the result is made (``time.time_ns``): the latency runs from the exposure to it.
    truth : TruthErrors, optional
        Simulated devices only.

    Returns
    -------
    StationResult
        Without ``output`` (the output stage adds what it sent).
    """
    exposure_ns = frames[0].host_time_ns
    coefficients = outcome.coefficients_waves
    statistics = outcome.statistics
    return StationResult(
        index=index, frame_ids=tuple(f.frame_id for f in frames), exposure_time_ns=exposure_ns,
        latency_ms=(now_ns - exposure_ns) * 1e-6, valid=outcome.valid, reason=outcome.reason,
        coefficients=tuple(float(c) for c in coefficients) if coefficients is not None else (),
        ordering=ordering, normalisation=outcome.normalisation, units="waves", residual_rms=statistics.residual_rms,
        residual_pv=statistics.residual_pv, pv=statistics.pv, pvr=statistics.pvr, quality=outcome.quality, fitter=outcome.fitter_kind, fitter_fallback=outcome.fitter_fallback,
        fitter_diagnostics=outcome.diagnostics, aperture=outcome.aperture_record, unwrap_path=outcome.unwrap_path,
        counters=counters, timings_ms={k: v * 1e3 for k, v in outcome.timings_s.items()},
        truth_rms=truth.truth_rms if truth is not None else None,
        truth_error_rms=truth.error_rms if truth is not None else None, calibration=outcome.calibration)


def with_output(result: StationResult, output: OutputRecord | None, *, now_ns: int | None = None) -> StationResult:
    """The result with what the output stage sent for it.

    ``now_ns`` (``time.time_ns`` after the send): the latency then runs to the end of the PLC
    exchange, as a result's latency always has (the result is complete once it is sent).
    """
    if output is None:
        return result
    if now_ns is None:
        return replace(result, output=output)
    return replace(result, output=output, latency_ms=(now_ns - result.exposure_time_ns) * 1e-6)


@dataclass(frozen=True, eq=False)
class CycleRecord:
    """Everything a sink gets about one cycle.

    Attributes
    ----------
    result : StationResult
        The result, with what went to the PLC (``result.output``).
    frames : tuple of Frame
        The set (empty when the device was lost).
    new_aperture_mask : ndarray of bool or None
        The full-resolution aperture when this set started a new one (interferometer), for the
        recording.
    lenslets : LensletSlopes or None
        Shack-Hartmann: the slopes per lenslet and the lenslets used (a frozen value).
    waves : ndarray (rows, cols) or None
        Interferometer: the unwrapped wavefront on the fit's grid (every ``fit_decimation``-th
        pixel), waves, NaN outside the aperture and wherever the quality mask left a pixel out,
        as the processor made it (never mutated after); None when the set gave none. The
        polishing loop averages these into its surface map.
    flags : ndarray of uint8 (rows, cols) or None
        Interferometer: the quality marks of each pixel of ``waves``
        (:mod:`wavestack.pipeline.instrument.quality`), for the live view.
    """

    result: StationResult
    frames: tuple[Frame, ...] = ()
    new_aperture_mask: NDArray[np.bool_] | None = None
    lenslets: LensletSlopes | None = None
    waves: NDArray[np.floating] | None = None
    flags: NDArray[np.uint8] | None = None


#: A result sink: the live view, the JSON lines, the recording.
ResultSink = Callable[[CycleRecord], None]
