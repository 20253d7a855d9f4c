"""The terminal's live view: a few lines refreshed in place while the station runs.

:class:`LiveStats` accumulates results (pure, testable); :func:`render_live_view` turns it into
lines; the run command writes them with an ANSI "cursor up" so the block refreshes in place.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from wavestack.pipeline.instrument import PixelQuality
from wavestack.station.counters import Counters
from wavestack.station.results import StationResult
from wavestack.station.surface_stage import SurfaceRecord

_TREND_THRESHOLD = 1e-3  # waves; smaller changes show as steady


@dataclass(frozen=True)
class LiveSnapshot:
    """What the live view shows at one moment."""

    results: int
    valid: int
    results_per_s: float
    latency_p50_ms: float
    latency_p99_ms: float
    counters: Counters | None  # frames and sets, as of the last result
    aperture: str
    fitter: str
    leading: tuple[tuple[int, float, float], ...]  # (index, value, change over the window), waves
    truth_error_rms: float | None
    last_reason: str | None
    residual: tuple[float, float] | None = None  # (rms, pv) of the last valid result's fit residual, waves
    figures: tuple[float, float] | None = None  # (pv, pvr) of the last valid result's wavefront, waves
    quality: PixelQuality | None = None  # what the last valid result's data-quality mask left out
    surface: str | None = None  # the last surface figures and verdict, one line


class LiveStats:
    """Rolling statistics over the last ``window`` results.

    Parameters
    ----------
    window : int
        Results kept for rates, percentiles and trends.
    leading : int
        How many leading coefficients to show (after piston and tilts).
    """

    def __init__(self, window: int = 100, leading: int = 6) -> None:
        self._times_ns: deque[int] = deque(maxlen=window)
        self._latencies: deque[float] = deque(maxlen=window)
        self._coefficients: deque[tuple[float, ...]] = deque(maxlen=window)
        self._leading = leading
        self._count = 0
        self._valid = 0
        self._last: StationResult | None = None
        self._last_reason: str | None = None
        self._residual: tuple[float, float] | None = None
        self._figures: tuple[float, float] | None = None
        self._quality: PixelQuality | None = None
        self._surface: str | None = None

    def add(self, result: StationResult, now_ns: int) -> None:
        """Account for one result received at host time ``now_ns``."""
        self._count += 1
        self._times_ns.append(now_ns)
        self._latencies.append(result.latency_ms)
        if result.valid:
            self._valid += 1
            self._coefficients.append(result.coefficients)
            self._residual = (result.residual_rms, result.residual_pv)
            self._figures = (result.pv, result.pvr)
            self._quality = result.quality
            if result.surface is not None:
                self._surface = surface_line(result.surface)
        else:
            self._last_reason = result.reason
        self._last = result

    def snapshot(self) -> LiveSnapshot:
        """The current view."""
        last = self._last
        rate = 0.0
        if len(self._times_ns) >= 2 and self._times_ns[-1] > self._times_ns[0]:
            rate = (len(self._times_ns) - 1) / ((self._times_ns[-1] - self._times_ns[0]) * 1e-9)
        latencies = np.asarray(self._latencies) if self._latencies else np.asarray([math.nan])
        leading: tuple[tuple[int, float, float], ...] = ()
        if self._coefficients:
            first, newest = self._coefficients[0], self._coefficients[-1]
            shown = range(3, min(len(newest), 3 + self._leading))  # skip piston and tilts
            leading = tuple((j + 1, newest[j], newest[j] - first[j]) for j in shown)
        if last is None:
            aperture, fitter = "-", "-"
        else:
            a = last.aperture
            # topology names the pixel count
            aperture = "#- -" if a is None else f"#{a.id} {a.topology}"
            fitter = (last.fitter or "-") + (" (fallback, building)" if last.fitter_fallback else "")
        return LiveSnapshot(
            results=self._count, valid=self._valid, results_per_s=rate,
            latency_p50_ms=float(np.nanpercentile(latencies, 50)) if np.isfinite(latencies).any() else math.nan,
            latency_p99_ms=float(np.nanpercentile(latencies, 99)) if np.isfinite(latencies).any() else math.nan,
            counters=last.counters if last else None, aperture=aperture, fitter=fitter, leading=leading,
            truth_error_rms=last.truth_error_rms if last else None, last_reason=self._last_reason,
            residual=self._residual, figures=self._figures, quality=self._quality, surface=self._surface,
        )


def _trend(change: float) -> str:
    if abs(change) < _TREND_THRESHOLD:
        return "="
    return "+" if change > 0 else "-"


def render_live_view(snapshot: LiveSnapshot, ordering: str) -> list[str]:
    """Lines of the live view (no terminal control codes)."""
    s = snapshot
    lines = [
        f"results {s.results} ({s.valid} valid)  {s.results_per_s:5.1f}/s  "
        f"latency p50 {s.latency_p50_ms:6.1f} ms  p99 {s.latency_p99_ms:6.1f} ms",
        *counter_lines(s.counters),
        f"aperture {s.aperture}   fitter {s.fitter}",
    ]
    if s.leading:
        terms = "  ".join(f"Z{j}={value:+.4f}{_trend(change)}" for j, value, change in s.leading)
        lines.append(f"waves ({ordering}): {terms}")
    if s.figures is not None and any(math.isfinite(v) for v in s.figures):
        lines.append(f"wavefront: pv {s.figures[0]:.4f}  pvr {s.figures[1]:.4f} waves")
    if s.residual is not None:
        lines.append(f"fit residual: rms {s.residual[0]:.4f}  pv {s.residual[1]:.4f} waves")
    if s.quality is not None:
        lines.append(quality_line(s.quality))
    if s.surface is not None:
        lines.append(s.surface)
    if s.truth_error_rms is not None:
        lines.append(f"error against the simulated truth: {s.truth_error_rms:.4f} waves rms")
    if s.last_reason:
        lines.append(f"last invalid: {s.last_reason}")
    return lines


def quality_line(quality: PixelQuality) -> str:
    """The pixels the last result used, and why the others inside the aperture were left out."""
    q = quality
    return (f"pixels used {q.used} of {q.inside}: left out {q.excluded} (low modulation {q.low_modulation}, "
            f"saturated {q.saturated}, fringe order {q.untrusted_order}, clipped {q.clipped}, rim {q.rim})")


def surface_line(record: SurfaceRecord) -> str:
    """The live view's line of a result's surface figures: the verdict first, then SAG, IRR, RSI, PVr."""
    form = record.form
    verdict = "" if record.verdict is None else (
        f"{record.verdict.tolerance.notation} {'PASS' if record.verdict.passed else 'FAIL'} "
        f"(limiting {record.verdict.limiting.quantity})  ")
    return (f"surface: {verdict}SAG {form.sag_nm:+.1f}  IRR {form.irr_nm:.1f}  RSI {form.rsi_nm:.1f}  "
            f"RMSi {form.rmsi_nm:.2f}  PVr {record.pvr.pvr:.1f} nm")


def counter_lines(counters: Counters | None) -> list[str]:
    """Frames and sets, each as its invariant: ``acquired = processed + dropped + pending``."""
    if counters is None:
        return ["frames acquired 0", "sets assembled 0"]
    f, c = counters.frames, counters.sets
    return [f"frames acquired {f.acquired} = {f.processed} in processed sets + {f.dropped} dropped + "
            f"{f.pending} pending",
            f"sets of {counters.frames_per_set} assembled {c.assembled} = {c.processed} processed + "
            f"{c.dropped} dropped + {c.pending} pending"]
