"""Soak of the simulated station: run it for a given time under a seeded random fault schedule.

Run:  .venv/bin/python benchmarks/soak.py --duration-s 600 --seed 1 [--fault-every-s 10] [--json]
      .venv/bin/python benchmarks/soak.py --list-faults

Builds the station ``wavestack run`` builds (the embedded default configuration unless
``--config``: every device simulated, 1024 x 1024 five-step phase-shifted sets, PLC output on)
and runs it in a thread. A scheduler thread injects a fault every ``--fault-every-s`` (+-25 %,
counted from the station's first result), kind and parameters drawn from ``--seed``, through the
simulators' own switches only (camera unplug/replug and stream faults, piezo garbage, silence,
split replies, unplug, PLC reply faults, delay, restart, frozen heartbeat echo, e-stop;
``--list-faults``). A monitor thread samples VmRSS (``/proc/self/status``), the peak RSS since
the previous sample (VmHWM, reset through ``/proc/self/clear_refs``) and the counters every
``--sample-every-s``.

A PLC watchdog trip is the designed fail-safe when a PLC fault kept the PLC out for longer than
the watchdog allows (``soak_trips``), a FAILURE otherwise; either way the soak acts as the operator:
``--operator-rearm-s`` after the trip (0: never) it re-arms the watchdog through a monitor link, as
``wavestack plc rearm`` does, and the same station goes on. What escapes the station (an exception
out of ``Station.run``) is recorded with the fault before it, and a fresh station is built on fresh
simulators so the run goes on; so is a stuck station (no valid result for ``--stuck-s`` while no
fault is active), unless ``--on-failure continue`` (a stuck station is only reported, a crash ends
the run) or ``stop``. Exceptions in any thread are caught by ``threading.excepthook``. Ctrl-C or
SIGTERM ends the run early, with the report.

Printed: a table over time (RSS, results, frame counters, faults so far), one row per fault
(its parameters, the signals it left in the results and counters, the time to the next valid
result, its problems), the faults by kind, every failure, and the verdict: the slope of the peak
RSS per sample window after the warm-up (the instantaneous RSS is reported beside it: once the
station gives freed memory back, ``[station] heap_release_s``, an instant sample lands anywhere in
the swing of one set's arrays; least squares, MB/min; over the last station's life only, a rebuilt
station's heap being new) and its largest deviation from the post-warm-up mean (target +-5 %), faults unaccounted for,
watchdog trips (fail-safe / FAILURE), operator re-arms and the commands the PLC accepted after them,
station rebuilds, commands sent while the PLC was not scanning (UNSAFE), unhandled exceptions, results per second. ``--tracemalloc`` adds
the allocation sites that grew from the end of the warm-up to the end, the station still running
(file:line, KiB, KiB/min, bytes per result); tracing slows the station and adds its own memory, so read RSS from a run without it. ``--json``
prints one JSON object instead. Exit status 0 when every target is met, 1 otherwise.
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import os
import random
import signal
import sys
import threading
import time
import traceback
import tracemalloc
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from soak_faults import (EXTRA_KINDS, FAULT_KINDS, Injection, ScheduledFault, Targets,
                         make_schedule, select_kinds)
from soak_observe import Observer, Window, device_snapshot
from soak_monitor import Monitor
from soak_operator import Operator
from soak_trips import TripLimits
from soak_report import growth_sites, render_text, rss_verdict, verdict_json
from soak_polish import PolishRunner

from wavestack.config import StationConfig, load_station_config
from wavestack.config.polishing import load_polishing_config
from wavestack.station import Station, StationSummary, counter_lines, open_station_devices

FAILURE_KINDS = ("station_crashes", "thread_exceptions", "stuck", "trip_failures", "failsafe_trips",
                 "operator_rearms", "rearm_errors", "startup_watchdog_trips", "counters_backwards", "injection_errors")


@dataclass
class Failures:
    """Every failure the soak saw, by kind, as one line each."""

    entries: dict[str, list[str]] = field(default_factory=lambda: {kind: [] for kind in FAILURE_KINDS})
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, kind: str, text: str) -> None:
        with self.lock:
            self.entries[kind].append(text)


class StationRunner:
    """Runs station after station in one thread: a crash or a restart request ends one, a fresh one follows."""

    def __init__(self, config: StationConfig, observer: Observer, failures: Failures, restart_on_failure: bool) -> None:
        self._config, self._observer, self._failures = config, observer, failures
        self._restart_on_failure = restart_on_failure
        self._lock = threading.Lock()
        self._devices: Any = None
        self._station_stop = threading.Event()
        self.stop = threading.Event()
        self.incarnation = 0
        self.started_t_s = 0.0
        self.crashes = self.restarts = self.past_trips = 0
        self.past_counters: Any = None
        self.summaries: list[StationSummary] = []

    @property
    def devices(self) -> Any:
        with self._lock:
            return self._devices

    def request_restart(self) -> None:
        """End the current station (its run returns); the runner builds a fresh one."""
        self._station_stop.set()

    def stop_all(self) -> None:
        self.stop.set()
        self._station_stop.set()

    def run(self) -> None:
        """Thread target: stations until :meth:`stop_all`."""
        while not self.stop.is_set():
            self._one_station()
            if self.stop.is_set() or not self._restart_on_failure:
                break
            self.restarts += 1
        self.stop.set()  # no station any more: the run ends

    def _one_station(self) -> None:
        self._station_stop = stop = threading.Event()
        if self.stop.is_set():
            stop.set()
        phase = "opening the devices"
        try:
            with ExitStack() as stack:
                devices = open_station_devices(self._config, stack)
                station = Station(self._config, devices)
                stack.callback(station.close)
                self._publish(devices)
                phase = "Station.run"
                self.summaries.append(station.run(stop=stop, on_result=self._observer.add))
                phase = "closing the station"
                self._retire()
        except Exception as error:  # noqa: BLE001 - the soak reports whatever escapes the station
            self.crashes += 1
            text = f"t={self._observer.now():.1f} s, {phase}, after {self._observer.current.kind} " \
                   f"#{self._observer.current.index}: {type(error).__name__}: {error}"
            where = traceback.extract_tb(error.__traceback__)[-1]
            text += f" (raised at {Path(where.filename).name}:{where.lineno})"
            self._failures.add("station_crashes", text)
            self._observer.record_crash(text)
            self._retire()

    def _publish(self, devices: Any) -> None:
        with self._lock:
            self._devices = devices
            self.incarnation += 1
        self.started_t_s = self._observer.now()

    def _retire(self) -> None:
        """Fold this station's counters and watchdog trips into the run's totals; no devices until the next."""
        devices = self.devices
        if devices is None:
            return
        if devices.plc_simulator is not None:
            self.past_trips += devices.plc_simulator.watchdog_trips
        last = self._observer.last_counters
        if last is not None:
            self.past_counters = last if self.past_counters is None else self.past_counters.plus(last)
        self._observer.last_counters = None
        self._observer.new_station()
        with self._lock:
            self._devices = None

    def totals(self) -> tuple[Any, int]:
        """Frame counters and PLC watchdog trips over every station so far."""
        devices, current = self.devices, self._observer.last_counters
        trips = self.past_trips + (devices.plc_simulator.watchdog_trips
                                   if devices is not None and devices.plc_simulator is not None else 0)
        if current is None:
            return self.past_counters, trips
        return (current if self.past_counters is None else self.past_counters.plus(current)), trips


def _targets(devices: Any) -> Targets:
    bench = devices.bench
    return Targets(camera=None if bench is None else bench.camera,
                   piezo=None if bench is None else getattr(bench, "piezo", None), plc=devices.plc_simulator)


class FaultScheduler:
    """Injects the schedule's faults from its own thread and opens a window for each."""

    def __init__(self, schedule: list[ScheduledFault], runner: StationRunner, observer: Observer,
                 failures: Failures) -> None:
        self._schedule, self._runner, self._observer, self._failures = schedule, runner, observer, failures
        self.stop = threading.Event()
        self.injected = 0
        self.first_result_t_s: float | None = None
        self.verbose = False
        self._last: tuple[Window, Injection] | None = None

    def run(self) -> None:
        """Thread target: the schedule, its times counted from the station's first result."""
        while self._observer.results == 0:  # a fault during start-up could not be told from start-up itself
            if self.stop.wait(0.1):
                return
        self.first_result_t_s = self._observer.now()
        for fault in self._schedule:
            if self.stop.wait(max(0.0, self.first_result_t_s + fault.t_s - self._observer.now())):
                return
            self._settle_last()
            self._inject(fault)

    def _inject(self, fault: ScheduledFault) -> None:
        devices, incarnation = self._runner.devices, self._runner.incarnation
        window = Window(fault.index, fault.kind.name, self._observer.now())
        if devices is None or self._observer.results_this_station == 0:
            # a fault while a fresh station starts could not be told from its start-up
            window.skipped = "no station: restarting" if devices is None else "station starting (no result yet)"
            self._observer.open_window(window, device_snapshot(devices), incarnation)
            return
        injection = fault.kind.inject(_targets(devices), random.Random(fault.seed))
        window.params, window.clear_t_s = injection.params, window.t_s + injection.duration_s
        window.plc_down_s, window.plc_reply_delay_s = injection.plc_down_s, injection.plc_reply_delay_s
        self._observer.open_window(window, device_snapshot(devices), incarnation)
        self.injected += 1
        self._last = (window, injection)
        if self.verbose:
            print(f"soak: t {window.t_s:6.1f} s  fault #{fault.index} {fault.kind.name} ({injection.params})",
                  file=sys.stderr)
        for delay, action in injection.steps:
            if delay > 0 and self.stop.wait(delay):
                return
            try:
                action()
            except Exception as error:  # noqa: BLE001 - a switch that fails is reported, the soak goes on
                self._failures.add("injection_errors", f"{fault.kind.name} #{fault.index}: "
                                                       f"{type(error).__name__}: {error}")
        window.clear_t_s = self._observer.now()

    def _settle_last(self) -> None:
        """Whether the last one-shot fault fired; switch it off if it did not."""
        if self._last is None:
            return
        window, injection = self._last
        self._last = None
        if injection.fired is not None:
            window.fired = bool(injection.fired())
            if not window.fired and injection.leftover is not None:
                injection.leftover()

    def finish(self) -> None:
        self.stop.set()
        self._settle_last()


class _LogCounter(logging.Handler):
    """Counts log records by level and logger (the station logs every fault it notices)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.counts: Counter[str] = Counter()

    def emit(self, record: logging.LogRecord) -> None:
        self.counts[f"{record.levelname} {record.name}"] += 1


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration-s", type=float, default=600.0, help="how long to run (default 600)")
    p.add_argument("--seed", type=int, default=1, help="seed of the fault schedule and its parameters")
    p.add_argument("--fault-every-s", type=float, default=10.0, help="mean time between faults; 0: no faults")
    p.add_argument("--faults", help="comma list of fault kinds or devices (camera, piezo, plc); default all")
    p.add_argument("--config", type=Path, help="station TOML (default: the embedded simulated station; with "
                                               "--polish, the embedded polishing station)")
    p.add_argument("--polish", action="store_true",
                   help="soak the polishing loop: campaigns back to back with job hand-offs (soak_polish)")
    p.add_argument("--polish-runs", type=int, default=2, help="runs per polishing campaign (default 2)")
    p.add_argument("--warmup-s", type=float, default=None, help="RSS verdict from here on (default: 20 %% of the run)")
    p.add_argument("--sample-every-s", type=float, default=5.0)
    p.add_argument("--table-every-s", type=float, default=30.0, help="rows of the printed table")
    p.add_argument("--stuck-s", type=float, default=30.0, help="no valid result / tripped watchdog this long: stuck")
    p.add_argument("--operator-rearm-s", type=float, default=3.0,
                   help="re-arm a tripped PLC watchdog this long after the trip, as `wavestack plc rearm` "
                        "(default 3; 0: never)")
    p.add_argument("--startup-s", type=float, default=120.0, help="no first result this long after a start: stuck")
    p.add_argument("--on-failure", choices=("restart", "continue", "stop"), default="restart",
                   help="after a crash or a stuck station: build a fresh one (default), or not (a stuck one "
                        "is only reported with 'continue'; a crash ends the run), or stop")
    p.add_argument("--slope-last-s", type=float, default=0.0,
                   help="also judge the slope of the peak RSS over the last S seconds (a shift: 1800 of a 3600 s "
                        "run), target --max-slope-mb-min; 0: not judged")
    p.add_argument("--max-slope-mb-min", type=float, default=0.1, help="the tail slope's target, MB/min")
    p.add_argument("--tracemalloc", action="store_true", help="print the allocation sites that grew")
    p.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    p.add_argument("--list-faults", action="store_true", help="print the fault kinds and exit")
    args = p.parse_args(argv)
    if args.warmup_s is None:
        args.warmup_s = 0.2 * args.duration_s
    return args


def _run_threads(args: argparse.Namespace, runner: StationRunner, scheduler: FaultScheduler,
                 monitor: Monitor, observer: Observer) -> None:
    threads = [threading.Thread(target=runner.run, name="soak-station"),
               threading.Thread(target=scheduler.run, name="soak-faults"),
               threading.Thread(target=monitor.run, name="soak-monitor")]
    for thread in threads:
        thread.start()
    while not runner.stop.wait(min(1.0, max(0.0, args.duration_s - observer.now()))):
        if observer.now() >= args.duration_s:
            break
    scheduler.finish()
    threads[1].join()
    observer.close(device_snapshot(runner.devices), runner.incarnation)
    if monitor.operator is not None:  # the station still runs: its PLC's accepted commands after each re-arm
        devices = runner.devices
        monitor.accepted_after_rearms = monitor.operator.accepted_after(
            devices.plc_simulator if devices is not None else None, runner.incarnation)
    monitor.stop.set()
    threads[2].join()
    monitor.sample(observer.now())
    if tracemalloc.is_tracing():  # the last snapshot while the station still runs: closing frees its histories
        gc.collect()
        monitor.end_snapshot, monitor.end_t_s, monitor.end_results = \
            tracemalloc.take_snapshot(), observer.now(), observer.results
    runner.stop_all()
    threads[0].join()


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.list_faults:
        for kind in FAULT_KINDS + EXTRA_KINDS:
            print(f"{kind.name:24s} {kind.device:7s} {kind.what}; expects {' or '.join(kind.expects) or 'nothing'}")
        return 0
    polishing = load_polishing_config(args.config) if args.polish else None
    config = polishing.station if polishing is not None else load_station_config(args.config)
    if polishing is not None:
        args.on_failure = "continue"  # a fault ends a campaign and the next begins: no station is rebuilt
    present = {"camera"} if config.camera.simulated else set()
    present |= {"piezo"} if config.phase_stepping and config.pzt is not None and config.pzt.url.startswith("sim://") \
        else set()
    present |= {"plc"} if config.plc is not None and config.outputs.enabled and config.plc.link.simulated else set()
    kinds = select_kinds(args.faults, present)
    schedule = make_schedule(args.seed, args.duration_s, args.fault_every_s, kinds)
    log_counter = _LogCounter()
    logging.getLogger().addHandler(log_counter)
    failures = Failures()
    hook = threading.excepthook

    def record_thread_exception(info: threading.ExceptHookArgs) -> None:
        name = info.thread.name if info.thread is not None else "?"
        failures.add("thread_exceptions", f"thread {name}: {info.exc_type.__name__}: {info.exc_value}")
        hook(info)

    threading.excepthook = record_thread_exception
    if args.tracemalloc:
        tracemalloc.start(1)
    started, load_at_start = time.monotonic(), os.getloadavg()
    observer = Observer(started)
    runner: Any = PolishRunner(polishing, observer, args.polish_runs) if polishing is not None else \
        StationRunner(config, observer, failures, restart_on_failure=args.on_failure == "restart")
    scheduler = FaultScheduler(schedule, runner, observer, failures)
    scheduler.verbose = not args.json
    plc = config.plc.link if config.plc is not None and config.outputs.enabled else None
    operator = Operator(plc, args.operator_rearm_s) if plc is not None and args.operator_rearm_s > 0 else None
    monitor = Monitor(args, runner, observer, failures, scheduler, operator,
                      TripLimits.from_link(plc) if plc is not None else None)
    for signum in (signal.SIGINT, signal.SIGTERM):  # end early, still with the report
        signal.signal(signum, lambda *_: runner.stop.set())
    _run_threads(args, runner, scheduler, monitor, observer)
    failures.entries["counters_backwards"] = list(observer.backwards)
    return _report(args, config, schedule, kinds, observer, runner, monitor, failures, log_counter, started,
                   scheduler.first_result_t_s, load_at_start)


def _rearms(monitor: Monitor) -> list[dict[str, Any]]:
    """Each operator re-arm, with the commands the PLC accepted after it (None: not known, -1: another station)."""
    if monitor.operator is None:
        return []
    after = monitor.accepted_after_rearms
    return [{"t_s": round(r.t_s, 1), "tripped_for_s": round(r.tripped_for_s, 1), "status": r.status,
             "accepted_after": after[k] if k < len(after) else None} for k, r in enumerate(monitor.operator.rearms)]


def _report(args: argparse.Namespace, config: StationConfig, schedule: list[ScheduledFault], kinds: tuple,
            observer: Observer, runner: StationRunner, monitor: Monitor, failures: Failures,
            log_counter: _LogCounter, started: float, first_result_t_s: float | None,
            load_at_start: tuple[float, float, float]) -> int:
    elapsed = time.monotonic() - started
    sites = None
    if monitor.warm_snapshot is not None and monitor.end_snapshot is not None:
        sites = growth_sites(monitor.warm_snapshot, monitor.end_snapshot, monitor.end_t_s - monitor.warm_t_s,
                             monitor.end_results - monitor.warm_results)
    load = f"load average {load_at_start[0]:.1f} at the start, {os.getloadavg()[0]:.1f} at the end on " \
           f"{os.cpu_count()} CPUs"
    station = f"station {config.source}: {config.station.kind}, {config.camera_simulator.width} x " \
              f"{config.camera_simulator.height}, {config.processing.method}" if config.camera.simulated \
        else f"station {config.source}"
    schedule_text = (f"seed {args.seed}, a fault every {args.fault_every_s:g} s +-25 % ({len(schedule)} scheduled) "
                     f"from {len(kinds)} kinds" if schedule else "no faults")
    run = {"command": " ".join(["benchmarks/soak.py", *(sys.argv[1:])]), "station": station, "load": load,
           "schedule": schedule_text, "duration_s": args.duration_s, "seed": args.seed, "elapsed_s": elapsed,
           "results": observer.results, "valid": observer.valid,
           "results_per_s": observer.results / elapsed if elapsed else 0.0,
           "station_runs": len(runner.summaries) + runner.crashes, "crashes": runner.crashes,
           "restarts": runner.restarts, "tracemalloc": args.tracemalloc,
           "first_result_t_s": first_result_t_s, "operator_rearm_s": args.operator_rearm_s,
           "rearms": _rearms(monitor),
           "log_counts": dict(log_counter.counts.most_common(12))}
    rss = rss_verdict(monitor.samples, args.warmup_s, measure="peak")
    instant = rss_verdict(monitor.samples, args.warmup_s, measure="rss")
    report = verdict_json(run, monitor.samples, rss, observer.windows, failures.entries, sites, instant)
    lines: list[str] = []
    if isinstance(runner, PolishRunner):  # the polishing loop: nothing applied twice, nothing lost
        report["polish"] = runner.final | {"error": runner.error}
        report["targets"]["polish_nothing_twice_nothing_lost"] = not runner.final.get("problems", ["no checks"]) \
            and not runner.error
        report["passed"] = all(report["targets"].values())
        lines.append(f"polishing: {runner.final.get('campaigns', 0)} campaigns "
                     f"({runner.final.get('campaign_ends', {})}), {runner.final.get('jobs', 0)} jobs handed off "
                     f"({runner.final.get('machine_states', {})}), the machine loaded "
                     f"{runner.final.get('machine_ids', 0)}; problems: {runner.final.get('problems') or 'none'}"
                     f"{'; ' + runner.error if runner.error else ''}")
    if args.slope_last_s > 0:  # a shift: the slope over the last stretch, once bounded histories are full
        tail = rss_verdict(monitor.samples, max(args.warmup_s, observer.now() - args.slope_last_s), measure="peak")
        report["rss_tail"] = {"last_s": args.slope_last_s, "slope_mb_per_min": tail.slope_mb_per_min,
                              "samples": tail.samples, "mean_mb": tail.mean_mb, "target_mb_per_min": args.max_slope_mb_min}
        report["targets"]["rss_tail_slope"] = bool(tail.slope_mb_per_min <= args.max_slope_mb_min)
        report["passed"] = all(report["targets"].values())
        lines.append(f"peak RSS slope over the last {args.slope_last_s:g} s: {tail.slope_mb_per_min:+.3f} MB/min "
                     f"({tail.samples} samples, mean {tail.mean_mb:.1f} MB; target <= {args.max_slope_mb_min:g})")
    summary = runner.summaries[-1] if runner.summaries else None
    lines += [f"station runs {run['station_runs']} (crashes {runner.crashes}, restarts {runner.restarts}); "
             f"log: " + ", ".join(f"{k} {v}" for k, v in run["log_counts"].items())]
    if summary is not None:
        lines += [f"last station's summary: {summary.results} results ({summary.valid} valid) in "
                  f"{summary.duration_s:.1f} s, latency p50 {summary.latency_p50_ms:.0f} ms, p99 "
                  f"{summary.latency_p99_ms:.0f} ms", *counter_lines(summary.counters)]
        report["last_summary"] = summary.to_json()
    else:
        lines.append("no station ended with a summary")
        report["last_summary"] = None
    if args.json:
        print(json.dumps(report))
    else:
        print(render_text(report, monitor.samples, observer.windows, args.table_every_s, lines), end="")
    return 0 if report["passed"] and (summary is not None or isinstance(runner, PolishRunner)) else 1


if __name__ == "__main__":
    sys.exit(main())
