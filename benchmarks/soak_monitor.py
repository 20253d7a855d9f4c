"""The soak's monitor thread: samples VmRSS and the counters, classifies PLC watchdog trips, plays the operator.

Each PLC watchdog trip is classified (:mod:`soak_trips`): fail-safe after a PLC outage longer than
the watchdog, else a FAILURE. A tripped watchdog is re-armed by the operator (:mod:`soak_operator`)
``--operator-rearm-s`` after it was first seen, and the same station goes on.

A station is *stuck* when it has produced no valid result for ``--stuck-s`` seconds while no fault
is active (counted from the station's own start), or no result at all ``--startup-s`` after it
started (a loaded machine starts slowly). The monitor then asks the runner for a fresh station
(``--on-failure restart``), stops the soak (``stop``) or only reports it (``continue``). A
watchdog still tripped after ``--stuck-s`` (outputs silent: the operator's re-arm failed or is
off) is reported as stuck too, but no fresh station is built for it: an operator re-arm, not a
rebuild, recovers a trip.
"""

from __future__ import annotations

import argparse
import gc
import sys
import threading
import tracemalloc
from typing import Any

from soak_observe import Observer, Window
from soak_operator import Operator
from soak_report import Sample
from soak_trips import FAILSAFE, FAILURE, TripLimits, classify_trip

__all__ = ["Monitor", "peak_rss_mb", "rss_mb"]


def rss_mb() -> float:
    """This process's resident set (VmRSS), MB."""
    with open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("/proc/self/status has no VmRSS line")


def peak_rss_mb() -> float | None:
    """The largest resident set since the last call (VmHWM, then reset), MB; None if it cannot be reset.

    Writing ``5`` to ``/proc/self/clear_refs`` resets the peak to the current RSS (Linux >= 4.0,
    ``man 5 proc``); without the reset VmHWM is the peak over the process's life, which says
    nothing about a window, so None is returned.
    """
    with open("/proc/self/status", encoding="ascii") as status:
        peak = next((int(line.split()[1]) / 1024 for line in status if line.startswith("VmHWM:")), None)
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as clear:
            clear.write("5")
    except OSError:
        return None
    return peak


class Monitor:
    """Samples RSS and counters, notices PLC watchdog trips and stuck stations."""

    def __init__(self, args: argparse.Namespace, runner: Any, observer: Observer, failures: Any,
                 scheduler: Any, operator: Operator | None = None, limits: TripLimits | None = None) -> None:
        self._args, self._runner, self._observer, self._failures = args, runner, observer, failures
        self._scheduler, self.operator, self._limits = scheduler, operator, limits
        self.stop = threading.Event()
        self.samples: list[Sample] = []
        self.warm_snapshot: tracemalloc.Snapshot | None = None
        self.warm_t_s = 0.0
        self.warm_results = 0
        self.end_snapshot: tracemalloc.Snapshot | None = None
        self.end_t_s = 0.0
        self.end_results = 0
        self._trips_seen = 0
        self._tripped_since: float | None = None
        self._stuck_key: tuple[int, int] | None = None
        self._next_sample = 0.0
        peak_rss_mb()  # the first window starts now
        self.accepted_after_rearms: list[int] = []  # filled at the end of the run

    def run(self) -> None:
        while not self.stop.wait(0.5):
            t = self._observer.now()
            self._watch(t)
            if t >= self._next_sample:
                self._next_sample = t + self._args.sample_every_s
                self.sample(t)
            if self._args.tracemalloc and self.warm_snapshot is None and t >= self._args.warmup_s:
                gc.collect()
                self.warm_snapshot, self.warm_t_s = tracemalloc.take_snapshot(), self._observer.now()
                self.warm_results = self._observer.results

    def sample(self, t: float) -> None:
        counters, _ = self._runner.totals()
        frames = counters.frames if counters is not None else None
        traced = tracemalloc.get_traced_memory()[0] / 2**20 if tracemalloc.is_tracing() else None
        sample = Sample(round(t, 1), rss_mb(), traced, self._observer.results, self._observer.valid,
                        frames.acquired if frames else 0, frames.processed if frames else 0,
                        frames.dropped if frames else 0, self._scheduler.injected, self._runner.crashes,
                        self._runner.restarts, peak_rss_mb())
        self.samples.append(sample)
        if not self._args.json:
            peak = "-" if sample.peak_mb is None else f"{sample.peak_mb:.1f}"
            print(f"soak: t {sample.t_s:6.0f} s  RSS {sample.rss_mb:7.1f} MB  peak {peak} MB  results {sample.results:6d} "
                  f"({sample.valid} valid)  faults {sample.faults}  crashes {sample.crashes}", file=sys.stderr)

    def _watch(self, t: float) -> None:
        _, trips = self._runner.totals()
        if trips > self._trips_seen:
            self._on_trips(t, trips - self._trips_seen)
            self._trips_seen = trips
        devices = self._runner.devices
        plc = devices.plc_simulator if devices is not None else None
        tripped = plc is not None and plc.watchdog_state.value == "tripped"
        self._tripped_since = (self._tripped_since or t) if tripped else None
        if tripped and self.operator is not None and self.operator.due(t, self._tripped_since):
            self._rearm(t, plc)
        self._check_stuck(t, self._observer.current)

    def _on_trips(self, t: float, count: int) -> None:
        """Classify ``count`` new trips: at start-up (the station re-arms itself), fail-safe, or FAILURE."""
        window = self._observer.current
        if not self._observer.sent_this_station:  # before this station's first command it re-arms a trip itself
            window.startup_trips += count
            self._failures.add("startup_watchdog_trips", f"t={t:.1f} s: PLC watchdog tripped (x{count}) after "
                                                         f"{window.kind} #{window.index} before this station's "
                                                         "first command")
            return
        if self._limits is None:
            verdict, cause = FAILURE, window
        else:
            verdict, cause = classify_trip(t, list(self._observer.windows), self._limits)
        if verdict == FAILSAFE:
            cause.trips_failsafe += count
            self._failures.add("failsafe_trips", f"t={t:.1f} s: PLC watchdog tripped (x{count}) after {cause.kind} "
                                                 f"#{cause.index} ({cause.params}): fail-safe")
        else:
            cause.trips_failure += count
            self._failures.add("trip_failures", f"t={t:.1f} s: PLC watchdog tripped (x{count}) after {cause.kind} "
                                                f"#{cause.index} ({cause.params}): no PLC outage of >= "
                                                f"{self._limits.outage_s if self._limits else 0:.2f} s explains it")

    def _rearm(self, t: float, plc: Any) -> None:
        """The operator's ``wavestack plc rearm``; the same station goes on."""
        assert self.operator is not None and self._tripped_since is not None
        done = self.operator.rearm(plc, self._runner.incarnation, t, self._tripped_since)
        if done is None:
            self._failures.add("rearm_errors", self.operator.errors[-1])
            return
        self._observer.current.rearms += 1
        self._failures.add("operator_rearms", f"t={t:.1f} s: operator re-armed the PLC watchdog (tripped "
                                              f"{done.tripped_for_s:.1f} s; status after: {done.status})")
        self._tripped_since = None

    def _check_stuck(self, t: float, window: Window) -> None:
        if self._runner.devices is None or (window.clear_t_s is not None and t < window.clear_t_s):
            return  # restarting, or a fault still active
        # counted from this station's start, not from the last fault: with a fault every 10 s a dead
        # station would otherwise never be quiet long enough to be called stuck
        start = self._runner.started_t_s
        limit, why = self._args.stuck_s, None
        if self._observer.results_this_station == 0:  # start-up (first aperture, fitter): its own limit
            if t - start > self._args.startup_s:
                why = f"no result {t - start:.0f} s after the station started"
        elif t - max(self._observer.last_valid_t_s, start) > limit:
            why = f"no valid result for {t - max(self._observer.last_valid_t_s, start):.0f} s"
        elif self._tripped_since is not None and t - max(self._tripped_since, start) > limit:
            why = f"PLC watchdog tripped for {t - max(self._tripped_since, start):.0f} s (outputs silent)"
        key = (window.index, self._runner.incarnation)
        if why is None or key == self._stuck_key:
            return
        self._stuck_key = key
        text = f"t={t:.1f} s: {why} after {window.kind} #{window.index}"
        window.stuck = why
        self._failures.add("stuck", text)
        if why.startswith("PLC watchdog"):
            return  # only an operator re-arm recovers a trip: a fresh station would only hide it
        if self._args.on_failure == "restart":
            self._runner.request_restart()
        elif self._args.on_failure == "stop":
            self._runner.stop_all()
