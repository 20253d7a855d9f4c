"""What the soak sees of the station: every result sorted into the window of the fault before it.

The station's ``on_result`` calls :meth:`Observer.add` once per result (cheap: a few counts under a
lock, nothing kept per result). Results from one fault's injection to the next belong to that
fault's :class:`Window`; results before the first fault to the baseline window (index -1). At the
start and end of each window the soak also reads the device counters (:func:`device_snapshot`:
the camera driver's stream health, the PLC link's reconnects, the simulators' replugs and
watchdog trips), so a fault the results do not show may still show in the counters.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

__all__ = ["SIGNALS", "Observer", "Window", "device_snapshot"]

# the signals a fault may leave; the first group comes from results, the rest from device counters
RESULT_SIGNALS = ("device_lost", "invalid", "heartbeat_errors", "plc_not_sent", "estop_seen")
DEVICE_SIGNALS = ("discarded_blocks", "stalls_cleared", "stream_timeouts", "transfer_errors", "frame_gap",
                  "link_reconnects", "camera_replugs", "watchdog_trips")
SIGNALS = RESULT_SIGNALS + DEVICE_SIGNALS
_MAX_REASONS = 4  # distinct invalid reasons kept per window


def device_snapshot(devices: Any) -> dict[str, int]:
    """The device counters of one station incarnation now (missing devices count 0)."""
    snap = dict.fromkeys(DEVICE_SIGNALS, 0)
    snap["watchdog_tripped_now"] = 0
    if devices is None:
        return snap
    try:
        c = devices.camera.counters()
        snap.update(discarded_blocks=c.discarded_blocks, stalls_cleared=c.stalls_cleared,
                    stream_timeouts=c.stream_timeouts, transfer_errors=c.transfer_errors, frame_gap=c.dropped_in_gaps)
    except Exception:  # noqa: BLE001 - a closed or lost camera has no counters to read; they count 0
        pass
    if devices.link is not None:
        snap["link_reconnects"] = devices.link.reconnects
    if devices.bench is not None:
        snap["camera_replugs"] = devices.bench.camera.session
    if devices.plc_simulator is not None:
        snap["watchdog_trips"] = devices.plc_simulator.watchdog_trips
        snap["watchdog_tripped_now"] = int(devices.plc_simulator.watchdog_state.value == "tripped")
    return snap


def _delta(start: dict[str, int], end: dict[str, int], same_station: bool) -> dict[str, int]:
    """Growth of each counter; across a station restart (or a counter that restarted) the end value."""
    return {k: end[k] - start[k] if same_station and end[k] >= start[k] else end[k] for k in DEVICE_SIGNALS}


@dataclass
class Window:
    """One fault (index >= 0) or the baseline (index -1), and what followed it until the next fault."""

    index: int
    kind: str
    t_s: float
    params: str = ""
    clear_t_s: float | None = None
    fired: bool | None = None
    skipped: str | None = None
    end_t_s: float | None = None
    results: int = 0
    valid: int = 0
    counts: Counter[str] = field(default_factory=Counter)
    reasons: Counter[str] = field(default_factory=Counter)
    first_valid_after_clear_s: float | None = None
    first_sent_after_clear_s: float | None = None
    devices: dict[str, int] = field(default_factory=dict)
    crashes: list[str] = field(default_factory=list)
    stuck: str | None = None
    startup_trips: int = 0
    trips_failsafe: int = 0  # PLC watchdog trips this fault explains (a PLC outage longer than the watchdog)
    trips_failure: int = 0  # trips while this window was current that no PLC outage explains
    rearms: int = 0  # operator re-arms while this window was current
    plc_down_s: float = 0.0
    plc_reply_delay_s: float = 0.0
    tripped_at_end: bool = False
    incarnation: int = 0
    start_snapshot: dict[str, int] = field(default_factory=dict)

    def signals(self) -> dict[str, int]:
        """Non-zero signals: results (device lost, invalid, ...) and device counter growth."""
        merged = {name: self.counts.get(name, 0) for name in RESULT_SIGNALS}
        merged.update(self.devices)
        return {name: value for name, value in merged.items() if value}

    def to_json(self) -> dict[str, object]:
        return {"index": self.index, "kind": self.kind, "t_s": round(self.t_s, 2), "params": self.params,
                "clear_t_s": None if self.clear_t_s is None else round(self.clear_t_s, 2), "fired": self.fired,
                "skipped": self.skipped, "results": self.results, "valid": self.valid, "signals": self.signals(),
                "reasons": dict(self.reasons), "recovered_after_s": _round(self.first_valid_after_clear_s),
                "outputs_resumed_after_s": _round(self.first_sent_after_clear_s), "crashes": self.crashes,
                "stuck": self.stuck, "startup_watchdog_trips": self.startup_trips,
                "failsafe_trips": self.trips_failsafe, "trip_failures": self.trips_failure,
                "operator_rearms": self.rearms,
                "watchdog_tripped_at_end": self.tripped_at_end}


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 2)


def _classify(result: Any) -> list[str]:
    """The signals one result carries."""
    found = []
    if not result.valid:
        found.append("device_lost" if (result.reason or "").startswith("device:") else "invalid")
    output = result.output
    if output is not None:
        beat = output.heartbeat
        if beat is not None and not beat.ok:
            found.append("heartbeat_errors")
        if beat is not None and beat.watchdog_tripped:  # read from the status, or a heartbeat refused by a trip
            found.append("watchdog_tripped_results")
        if beat is not None and beat.estop:
            found.append("estop_seen")
        if output.command.sent:
            found.append("sent")
        elif (output.command.reason or "").startswith("PLC:"):
            found.append("plc_not_sent")
    return found


class Observer:
    """Counts results into fault windows; thread-safe (the station, scheduler and sampler threads share it)."""

    def __init__(self, started: float) -> None:
        self._started = started
        self._lock = threading.Lock()
        self.windows: list[Window] = [Window(-1, "baseline", 0.0)]
        self.results = self.valid = 0
        self.last_valid_t_s = 0.0
        self.last_counters: Any = None
        self.backwards: list[str] = []
        self.sent_this_station = False  # a command went to the PLC since this station started
        self.results_this_station = 0
        self._last_acquired = -1

    def now(self) -> float:
        """Seconds since the soak started."""
        return time.monotonic() - self._started

    @property
    def current(self) -> Window:
        return self.windows[-1]

    def add(self, record: Any) -> None:
        """One station result (a ``CycleRecord``)."""
        result, t = record.result, self.now()
        signals = _classify(result)
        with self._lock:
            window = self.current
            seen_estop = window.counts.get("estop_seen", 0) > 0  # by an earlier result of this fault
            self.results += 1
            self.results_this_station += 1
            window.results += 1
            window.counts.update(signals)
            cleared = window.clear_t_s is not None and t >= window.clear_t_s
            if result.valid:
                self.valid += 1
                window.valid += 1
                self.last_valid_t_s = t
                if cleared and window.first_valid_after_clear_s is None:
                    window.first_valid_after_clear_s = t - window.clear_t_s
            else:
                key = _short(result.reason)
                if key in window.reasons or len(window.reasons) < _MAX_REASONS:
                    window.reasons[key] += 1
            self.sent_this_station |= "sent" in signals
            active = window.clear_t_s is not None and t < window.clear_t_s
            if "sent" in signals and active:
                window.counts["sent_while_active"] += 1  # a command while the fault was on
            status = (result.output.command.status or "") if result.output is not None else ""
            attempted = "sent" in signals or "NOT_SENT" in status  # sent, or sent and refused by the PLC
            if attempted and active and (seen_estop or "estop_seen" in signals):
                window.counts["commanded_after_estop_seen"] += 1  # the station knew, and still sent
            if "sent" in signals and cleared and window.first_sent_after_clear_s is None:
                window.first_sent_after_clear_s = t - window.clear_t_s
            self._check_counters(result.counters, t)

    def _check_counters(self, counters: Any, t: float) -> None:
        acquired = counters.frames.acquired
        if acquired < self._last_acquired:
            self.backwards.append(f"t={t:.1f} s: frames acquired {self._last_acquired} -> {acquired} "
                                  f"(after {self.current.kind})")
        self._last_acquired = acquired
        self.last_counters = counters

    def new_station(self) -> None:
        """A station incarnation ends (crash or restart): its counters start again from zero."""
        with self._lock:
            self._last_acquired = -1
            self.sent_this_station = False
            self.results_this_station = 0

    def open_window(self, window: Window, snapshot: dict[str, int], incarnation: int) -> Window:
        """Close the current window with ``snapshot`` and start ``window``."""
        with self._lock:
            self._close(snapshot, incarnation)
            window.start_snapshot, window.incarnation = snapshot, incarnation
            self.windows.append(window)
            return window

    def close(self, snapshot: dict[str, int], incarnation: int) -> None:
        """End the last window (end of the run)."""
        with self._lock:
            self._close(snapshot, incarnation)

    def _close(self, snapshot: dict[str, int], incarnation: int) -> None:
        window = self.current
        window.end_t_s = self.now()
        start = window.start_snapshot or dict.fromkeys(DEVICE_SIGNALS, 0)
        window.devices = _delta(start, snapshot, incarnation == window.incarnation)
        window.tripped_at_end = bool(snapshot.get("watchdog_tripped_now"))

    def record_crash(self, text: str) -> None:
        with self._lock:
            self.current.crashes.append(text)


def _short(reason: str | None) -> str:
    """An invalid result's reason without the numbers that make each one unique (for counting)."""
    text = (reason or "no reason")[:90]
    return "".join("#" if ch.isdigit() else ch for ch in text)
