"""The web view's feed: the station's sink and the loops' values write; the server's tick reads.

Writers (the station's pipeline thread, a loop's thread) only note what they got under a lock
(the web view reads values only: station records, a loop's phase and its
:class:`~wavestack.loop.LoopHistory`; it drives nothing):
a result goes into :class:`~wavestack.station.LiveStats` (the terminal view's numbers), a map is
kept by reference (the station never mutates a record's map after making it). Nothing is rendered
there, so the web view costs the pipeline a lock and a few additions per result.

The reader is the server's thread: :meth:`LiveFeed.update` builds a :class:`~wavestack.web.view.LiveUpdate`
when something changed, rendering the newest map at most once per ``min_render_s`` (a map that
arrives sooner waits for the next tick, and only the newest waiting map is rendered). Only one
thread may call :meth:`LiveFeed.update`.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.loop import LoopHistory
from wavestack.pipeline.instrument import PixelQuality
from wavestack.pipeline.zernike import first_index, index_to_nm, mode_name
from wavestack.station.cycle import CycleRecord
from wavestack.station.live_view import LiveSnapshot, LiveStats
from wavestack.station.results import FitDiagnostics, StationResult
from wavestack.station.surface_stage import SurfaceRecord
from wavestack.web.render import render_map
from wavestack.web.view import Coefficient, HistoryPanel, LiveUpdate, MapImage, StationPanel

__all__ = ["LiveFeed", "station_panel"]

_LEADING = 8  # coefficients shown after piston and tilts


@dataclass(frozen=True)
class _PendingMap:
    values: NDArray[np.floating]
    units: str
    title: str
    number: int
    flags: NDArray[np.uint8] | None = None


def _counts(counts: object, total: str) -> tuple[int, int, int, int]:
    return (getattr(counts, total), getattr(counts, "processed"), getattr(counts, "dropped"),
            getattr(counts, "pending"))


def _coefficient(label: int, value: float, change: float, ordering: str) -> Coefficient:
    index = label - 1 + first_index(ordering)  # LiveStats labels position p as p + 1
    try:
        name = mode_name(*index_to_nm(index, ordering))  # type: ignore[arg-type]
    except ValueError:
        name = ""
    return Coefficient(index, name, value, change)


def station_panel(snapshot: LiveSnapshot, newest: StationResult | None, shown: StationResult | None,
                  ordering: str) -> StationPanel:
    """The station's numbers from the live statistics, the newest result and the newest valid one (pure).

    Example
    -------
    >>> station_panel(LiveStats().snapshot(), None, None, "noll").results
    0
    """
    diagnostics = newest.fitter_diagnostics if newest is not None else None
    kappa = flips = max_mu = None
    if isinstance(diagnostics, FitDiagnostics):
        kappa, flips, max_mu = diagnostics.gram_condition, diagnostics.flips, diagnostics.max_beltrami
    elif diagnostics is not None:
        kappa = diagnostics.condition
    output = newest.output if newest is not None else None
    heartbeat = output.heartbeat if output is not None else None
    counters = snapshot.counters
    return StationPanel(
        results=snapshot.results, valid=snapshot.valid, last_index=newest.index if newest is not None else -1,
        shown_index=shown.index if shown is not None else -1, results_per_s=snapshot.results_per_s,
        latency_p50_ms=snapshot.latency_p50_ms, latency_p99_ms=snapshot.latency_p99_ms,
        frames=_counts(counters.frames, "acquired") if counters else (0, 0, 0, 0),
        sets=_counts(counters.sets, "assembled") if counters else (0, 0, 0, 0),
        frames_per_set=counters.frames_per_set if counters else 0, aperture=snapshot.aperture,
        fitter=snapshot.fitter, kappa=kappa, flips=flips, max_mu=max_mu, ordering=ordering,
        coefficients=tuple(_coefficient(j, v, c, ordering) for j, v, c in snapshot.leading),
        residual_rms=shown.residual_rms if shown is not None else None,
        residual_pv=shown.residual_pv if shown is not None else None,
        truth_error_rms=shown.truth_error_rms if shown is not None else None,
        safety=output.command.status if output is not None else None,
        sent=output.sent if output is not None else None,
        plc_state=heartbeat.state if heartbeat is not None else None,
        heartbeat_ok=heartbeat.ok if heartbeat is not None else None, last_reason=snapshot.last_reason,
        pv=shown.pv if shown is not None else None, pvr=shown.pvr if shown is not None else None,
        quality=_quality(shown.quality) if shown is not None else None,
        surface=_surface(shown.surface) if shown is not None else None,
        spec=_spec(shown.surface) if shown is not None else None)


def _quality(quality: PixelQuality | None) -> tuple[int, int, int, int, int, int, int] | None:
    if quality is None:
        return None
    q = quality
    return (q.inside, q.used, q.low_modulation, q.saturated, q.untrusted_order, q.clipped, q.rim)


def _surface(record: SurfaceRecord | None) -> tuple[float, float, float] | None:
    if record is None:
        return None
    return (record.form.irr_nm, record.form.rmst_nm, record.pvr.pvr)


def _spec(record: SurfaceRecord | None) -> tuple[str, bool, str] | None:
    if record is None or record.verdict is None:
        return None
    verdict = record.verdict
    return (verdict.tolerance.notation, verdict.passed, verdict.limiting.quantity)


class LiveFeed:
    """What the page shows, fed from any thread (module notes).

    Parameters
    ----------
    title : str
        The command, shown as the page's heading.
    ordering : str
        The coefficients' ordering.
    min_render_s : float
        Shortest time between two map renders, s.
    max_side : int
        Longest side of the map's PNG, pixels.
    clock : callable
        Seconds (``time.monotonic``); tests pass their own.

    Example
    -------
    >>> feed = LiveFeed("wavestack run")
    >>> feed.update().state
    'waiting'
    >>> feed.update() is None  # nothing new
    True
    """

    def __init__(self, title: str, *, ordering: str = "noll", min_render_s: float = 0.25, max_side: int = 200,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._title, self._ordering = title, ordering
        self._min_render_s, self._max_side, self._clock = min_render_s, max_side, clock
        self._lock = threading.Lock()
        self._version = 1
        self._stats = LiveStats(leading=_LEADING)
        self._records = 0
        self._newest: StationResult | None = None
        self._shown: StationResult | None = None
        self._map: _PendingMap | None = None
        self._ended: str | None = None
        self._phase = ("", "")
        self._history: LoopHistory | None = None
        self._history_seq = 0
        # the reader's own (update() runs on one thread)
        self._published = 0
        self._seq = 0
        self._image: MapImage | None = None
        self._rendered = 0  # number of the map in _image
        self._last_render_s = -math.inf
        self._render_ms_total = 0.0
        self._renders = 0

    # ------------------------------------------------------------------ writers (any thread)
    def __call__(self, record: CycleRecord) -> None:
        """The station's sink: note one cycle (a lock and a few additions; nothing rendered here)."""
        result = record.result
        with self._lock:
            self._stats.add(result, time.time_ns())
            self._records += 1
            self._newest = result
            if result.valid:
                self._shown = result
            if record.waves is not None:
                self._map = _PendingMap(record.waves, "waves", f"wavefront, result {result.index}",
                                        (self._map.number + 1) if self._map else 1, record.flags)
            self._version += 1

    def show_map(self, values: NDArray[np.floating], *, units: str, title: str) -> None:
        """Show this map next (a loop's measurement); kept by reference: do not modify it after."""
        with self._lock:
            self._map = _PendingMap(values, units, title, (self._map.number + 1) if self._map else 1)
            self._version += 1

    def loop_phase(self, phase: str, reason: str) -> None:
        """A loop's transition: its phase and why (``on_event`` of the polishing and alignment loops)."""
        with self._lock:
            self._phase = (phase, reason)
            self._history_seq += 1
            self._version += 1

    def show_history(self, history: LoopHistory) -> None:
        """A loop's history table as it stands now (it replaces the one shown)."""
        with self._lock:
            self._history = history
            self._history_seq += 1
            self._version += 1

    def end(self, reason: str) -> None:
        """The station or loop stopped (the first reason stays)."""
        with self._lock:
            if self._ended is None:
                self._ended = reason
                self._version += 1

    # ------------------------------------------------------------------ the reader (one thread)
    def update(self) -> LiveUpdate | None:
        """The page now, or None when nothing changed since the last call (module notes)."""
        now = self._clock()
        with self._lock:
            pending = self._map
            render_due = (pending is not None and pending.number != self._rendered
                          and now - self._last_render_s >= self._min_render_s)
            if self._version == self._published and not render_due:
                return None
            self._published = self._version
            snapshot = self._stats.snapshot() if self._records else None
            newest, shown, ended, phase = self._newest, self._shown, self._ended, self._phase
            history = self._history_panel()
        if render_due and pending is not None:
            self._image = render_map(pending.values, units=pending.units, title=pending.title, seq=pending.number,
                                     max_side=self._max_side, flags=pending.flags)
            self._rendered, self._last_render_s = pending.number, now
            self._render_ms_total += self._image.render_ms
            self._renders += 1
        state, detail = _state(newest, ended, phase, self._image is not None)
        self._seq += 1
        renders = self._renders
        panel = station_panel(snapshot, newest, shown, self._ordering) if snapshot is not None else None
        return LiveUpdate(self._seq, self._title, state, detail, panel, self._image, history, renders=renders,
                          render_ms_mean=self._render_ms_total / renders if renders else math.nan)

    def _history_panel(self) -> HistoryPanel | None:
        phase, reason = self._phase
        h = self._history
        if h is not None:
            return HistoryPanel(h.kind, self._history_seq, h.columns, h.rows, h.trend_label, h.trend, phase, reason)
        if phase:
            return HistoryPanel("", self._history_seq, (), (), "", (), phase, reason)
        return None


def _state(newest: StationResult | None, ended: str | None, phase: tuple[str, str],
           have_map: bool) -> tuple[str, str]:
    """The page's state line: waiting, running, device lost or stopped, and why."""
    if ended is not None:
        return "stopped", ended
    if newest is not None and not newest.valid and (newest.reason or "").startswith("device:"):
        return "device lost", newest.reason or ""
    if newest is not None:
        return "running", f"result {newest.index}" + ("" if newest.valid else f" invalid: {newest.reason}")
    if phase[0] or have_map:
        return "running", phase[0]
    return "waiting", "waiting for the first result"
