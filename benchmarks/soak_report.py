"""The soak's figures and verdict: RSS over time, faults against their evidence, failures; text and JSON.

Pure functions of what :mod:`soak_observe` and the sampler collected (no I/O but the returned
strings), so the verdict can be checked on hand-made samples.
"""

from __future__ import annotations

import os
import tracemalloc
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from soak_faults import FAULT_KINDS
from soak_observe import Window

__all__ = ["GrowthSite", "RssVerdict", "Sample", "fault_problems", "growth_sites", "render_text", "rss_verdict",
           "unsafe_commands", "verdict_json"]

_KINDS = {kind.name: kind for kind in FAULT_KINDS}
# faults during which no command may reach the PLC (issue 13: commands while the PLC is not scanning), how
# many may, and which count judges it: the echo had advanced since the previous command when the echo
# froze, so the link may send one more command before it can see that the PLC stopped scanning (and the
# result of a command sent just before the fault is counted in its window); a second one had no scan
# before it. The e-stop is in the status the station reads: once a result of the fault has shown it, no
# command may be tried (sent, or sent and refused); a command the PLC accepted just before the e-stop,
# whose result arrives after it, is not one
_NO_COMMANDS_WHILE = {"plc_freeze_echo": ("the heartbeat echo was frozen (PLC not scanning)", 1, "sent_while_active"),
                      "plc_estop": ("the e-stop was pressed and seen", 0, "commanded_after_estop_seen")}
RECOVERY_GRACE_S = 5.0  # a fault followed this soon by the next one is not judged on its recovery
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@dataclass(frozen=True)
class Sample:
    """One sample: time since start (s), VmRSS (MB), traced Python memory (MB, with --tracemalloc), counts.

    ``peak_mb`` is the largest resident set since the previous sample (VmHWM, reset after each
    sample through ``/proc/self/clear_refs``), None where the kernel does not allow the reset.
    """

    t_s: float
    rss_mb: float
    traced_mb: float | None
    results: int
    valid: int
    acquired: int
    delivered: int
    dropped: int
    faults: int
    crashes: int
    restarts: int
    peak_mb: float | None = None


@dataclass(frozen=True)
class RssVerdict:
    """RSS after the warm-up: least-squares slope, mean, largest deviation from the mean, and whether flat."""

    samples: int
    warmup_s: float
    slope_mb_per_min: float
    mean_mb: float
    first_mb: float
    last_mb: float
    max_deviation_pct: float
    tolerance_pct: float
    flat: bool
    traced_slope_mb_per_min: float | None = None
    station_run: int = 1
    station_runs: int = 1
    measure: str = "rss"


def rss_verdict(samples: list[Sample], warmup_s: float, tolerance_pct: float = 5.0,
                measure: str = "rss") -> RssVerdict:
    """Fit memory against time over the samples after ``warmup_s`` of the last station; flat if all within tolerance.

    ``measure`` is ``"rss"`` (VmRSS at each sample) or ``"peak"`` (the largest RSS in each
    sample's window, ``Sample.peak_mb``; falls back to ``"rss"`` when a sample has none). The
    station's working set swings by its per-set arrays (~100 MB on the default station) within
    a cycle, so an instantaneous sample lands anywhere in that swing once freed memory goes back
    to the system; the peak per window is the memory the station needs and is what a leak or
    a fragmenting heap makes grow.

    Only the last station's samples count (``Sample.restarts`` numbers the stations): a rebuilt
    station allocates a new heap (about 50 MB of arrays on the default station) while the
    allocator keeps the old one mapped, so RSS across a rebuild says nothing about a leak.

    Examples
    --------
    >>> s = [Sample(t, 100.0 + 0.01 * t, None, 0, 0, 0, 0, 0, 0, 0, 0) for t in range(0, 600, 5)]
    >>> v = rss_verdict(s, 60.0)
    >>> round(v.slope_mb_per_min, 2), v.flat
    (0.6, True)
    """
    station = samples[-1].restarts if samples else 0
    late = [s for s in samples if s.t_s >= warmup_s and s.restarts == station]
    if measure == "peak" and any(s.peak_mb is None for s in late):
        measure = "rss"
    if len(late) < 2:
        nan = float("nan")
        return RssVerdict(len(late), warmup_s, nan, nan, nan, nan, nan, tolerance_pct, False, None, station + 1,
                          station + 1, measure)
    t = np.array([s.t_s for s in late]) / 60.0
    rss = np.array([s.peak_mb if measure == "peak" else s.rss_mb for s in late], dtype=float)
    mean = float(rss.mean())
    deviation = float(np.max(np.abs(rss - mean)) / mean * 100.0)
    traced = [s.traced_mb for s in late]
    traced_slope = float(np.polyfit(t, np.array(traced), 1)[0]) if None not in traced else None
    return RssVerdict(len(late), warmup_s, float(np.polyfit(t, rss, 1)[0]), mean, float(rss[0]), float(rss[-1]),
                      deviation, tolerance_pct, deviation <= tolerance_pct, traced_slope, station + 1, station + 1,
                      measure)


@dataclass(frozen=True)
class GrowthSite:
    """An allocation site that grew between the warm-up snapshot and the last one."""

    where: str
    grew_kib: float
    blocks: int
    kib_per_min: float
    bytes_per_result: float


def growth_sites(before: tracemalloc.Snapshot, after: tracemalloc.Snapshot, span_s: float, results: int,
                 top: int = 15) -> list[GrowthSite]:
    """The ``top`` sites (file:line) by growth of their live allocations from ``before`` to ``after``.

    ``span_s`` and ``results`` are the time and the station results between the snapshots: growth
    per result does not depend on how fast a loaded machine runs the station.
    """
    ignore = [tracemalloc.Filter(False, tracemalloc.__file__), tracemalloc.Filter(False, "<frozen importlib*"),
              tracemalloc.Filter(False, "<unknown>")]
    diff = after.filter_traces(ignore).compare_to(before.filter_traces(ignore), "lineno")
    sites = []
    for stat in diff:
        if stat.size_diff <= 0:
            continue
        frame = stat.traceback[0]
        where = f"{os.path.relpath(frame.filename, _ROOT) if frame.filename.startswith(_ROOT) else frame.filename}" \
                f":{frame.lineno}"
        sites.append(GrowthSite(where, stat.size_diff / 1024, stat.count_diff, stat.size_diff / 1024 / span_s * 60,
                                stat.size_diff / max(1, results)))
        if len(sites) == top:
            break
    return sites


def unsafe_commands(window: Window) -> int:
    """Commands sent during a fault that forbids them, beyond those the link may send before it can see it."""
    if window.kind not in _NO_COMMANDS_WHILE:
        return 0
    _, allowed, count = _NO_COMMANDS_WHILE[window.kind]
    return max(0, window.counts.get(count, 0) - allowed)


def fault_problems(window: Window) -> list[str]:
    """What went wrong with one fault (empty: injected, seen in the counters/results, recovered)."""
    if window.skipped:
        return [f"skipped ({window.skipped})"]
    problems = [f"CRASH {text.splitlines()[0]}" for text in window.crashes]
    if window.stuck:
        problems.append(f"STUCK {window.stuck}")
    kind = _KINDS.get(window.kind)
    signals = window.signals()
    if window.fired is False:
        problems.append("never fired")
    elif kind is not None and kind.expects and not any(signals.get(name) for name in kind.expects):
        problems.append("UNACCOUNTED (expected " + " or ".join(kind.expects) + ")")
    unsafe = unsafe_commands(window)
    if unsafe:
        what, allowed, _ = _NO_COMMANDS_WHILE[window.kind]
        problems.append(f"UNSAFE: {unsafe} commands sent while {what}" + (f" (beyond the {allowed} the link may send "
                                                                            "before it can see it)" if allowed else ""))
    if window.trips_failure > 0:
        problems.append(f"WATCHDOG TRIPPED x{window.trips_failure} (FAILURE: no PLC outage explains it)")
    observed_s = (window.end_t_s or 0.0) - (window.clear_t_s or 0.0)
    if window.clear_t_s is not None and window.first_valid_after_clear_s is None and not window.crashes \
            and not window.stuck and observed_s >= RECOVERY_GRACE_S:
        problems.append(f"no valid result in the {observed_s:.0f} s after it cleared")
    if window.tripped_at_end and window.index >= 0:
        problems.append("outputs silent: PLC watchdog still tripped at the next fault")
    return problems


def _fault_rows(windows: list[Window]) -> list[str]:
    rows = ["| # | t s | kind | params | results (valid) | signals | recovered after s | problems |",
            "|---:|---:|---|---|---:|---|---:|---|"]
    for w in windows:
        signals = ", ".join(f"{k} {v}" for k, v in w.signals().items()) or "-"
        recovered = "-" if w.first_valid_after_clear_s is None else f"{w.first_valid_after_clear_s:.1f}"
        problems = "; ".join(fault_problems(w)) or "ok"
        rows.append(f"| {w.index} | {w.t_s:.1f} | {w.kind} | {w.params} | {w.results} ({w.valid}) | {signals} | "
                    f"{recovered} | {problems} |")
    return rows


def _by_kind(windows: list[Window]) -> dict[str, dict[str, int]]:
    table: dict[str, dict[str, int]] = {}
    for w in windows:
        if w.index < 0:
            continue
        row = table.setdefault(w.kind, {"injected": 0, "accounted": 0, "problems": 0, "crashes": 0,
                                        "failsafe_trips": 0, "trip_failures": 0, "operator_rearms": 0})
        problems = fault_problems(w)
        row["injected"] += not w.skipped
        row["accounted"] += not w.skipped and not any(p.startswith(("UNACCOUNTED", "never")) for p in problems)
        row["problems"] += bool(problems)
        row["crashes"] += len(w.crashes)
        row["failsafe_trips"] += w.trips_failsafe
        row["trip_failures"] += w.trips_failure
        row["operator_rearms"] += w.rearms
    return table


def verdict_json(run: dict[str, Any], samples: list[Sample], rss: RssVerdict, windows: list[Window],
                 failures: dict[str, list[str]], sites: list[GrowthSite] | None,
                 rss_instant: RssVerdict | None = None) -> dict[str, Any]:
    """Everything the soak measured, as one JSON-ready object (``targets`` says what held).

    ``rss`` is the verdict the target is judged on (the peak per window where the kernel gives
    it); ``rss_instant`` the same fit over the instantaneous samples, reported beside it.
    """
    faults = [w for w in windows if w.index >= 0]
    unaccounted = [w.index for w in faults if any(p.startswith("UNACCOUNTED") for p in fault_problems(w))]
    exceptions = len(failures["thread_exceptions"]) + len(failures["station_crashes"])
    unsafe = sum(unsafe_commands(w) for w in faults)
    station_failures = sum(len(failures[k]) for k in ("trip_failures", "stuck", "counters_backwards"))
    station_failures += len(failures["injection_errors"])
    station_failures += sum(1 for w in faults if any(p.startswith(("no valid", "outputs silent", "UNSAFE"))
                                                      for p in fault_problems(w)))
    targets = {"rss_flat": rss.flat, "faults_accounted": not unaccounted, "no_unhandled_exceptions": exceptions == 0,
               "no_station_failures": station_failures == 0}
    return {"type": "soak", "run": run, "samples": [asdict(s) for s in samples], "rss": asdict(rss),
            "rss_instant": None if rss_instant is None else asdict(rss_instant),
            "faults": [w.to_json() | {"problems": fault_problems(w)} for w in faults],
            "baseline": windows[0].to_json(), "by_kind": _by_kind(windows), "failures": failures,
            "unaccounted": unaccounted, "unhandled_exceptions": exceptions, "station_failures": station_failures,
            "failsafe_trips": len(failures["failsafe_trips"]), "trip_failures": len(failures["trip_failures"]),
            "operator_rearms": len(failures["operator_rearms"]), "unsafe_commands": unsafe,
            "growth_sites": None if sites is None else [asdict(s) for s in sites], "targets": targets,
            "passed": all(targets.values())}


def _sample_rows(samples: list[Sample], every_s: float) -> list[str]:
    rows = ["| t s | RSS MB | peak MB | traced MB | results | valid | frames acquired / delivered / dropped | "
            "faults | crashes | restarts |", "|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|"]
    next_t = 0.0
    for k, s in enumerate(samples):
        if s.t_s + 1e-6 < next_t and k != len(samples) - 1:
            continue
        next_t = s.t_s + every_s
        traced = "-" if s.traced_mb is None else f"{s.traced_mb:.1f}"
        peak = "-" if s.peak_mb is None else f"{s.peak_mb:.1f}"
        rows.append(f"| {s.t_s:.0f} | {s.rss_mb:.1f} | {peak} | {traced} | {s.results} | {s.valid} | "
                    f"{s.acquired} / {s.delivered} / {s.dropped} | {s.faults} | {s.crashes} | {s.restarts} |")
    return rows


def _rss_line(rss: dict[str, Any], role: str) -> str:
    what = "peak RSS per sample window" if rss["measure"] == "peak" else "RSS at each sample"
    target = f"target +-{rss['tolerance_pct']:g} %" if role == "judged" else "reported only"
    return (f"{what} after the {rss['warmup_s']:.0f} s warm-up, over one station's life (station run "
            f"{rss['station_run']}, {rss['samples']} samples): slope {rss['slope_mb_per_min']:+.3f} MB/min, "
            f"{rss['first_mb']:.1f} -> {rss['last_mb']:.1f} MB, mean {rss['mean_mb']:.1f} MB, max deviation "
            f"{rss['max_deviation_pct']:.2f} % ({target})")


def _rearm_text(run: dict[str, Any]) -> str:
    rearms = run.get("rearms", [])
    if not run.get("operator_rearm_s"):
        return "operator re-arms: off"
    after = [r["accepted_after"] for r in rearms if r["accepted_after"] is not None and r["accepted_after"] >= 0]
    text = f"operator re-arms: {len(rearms)} ({run['operator_rearm_s']:g} s after a trip)"
    return text + (f", PLC accepted {after[-1]} commands after the last" if after else "")


def render_text(report: dict[str, Any], samples: list[Sample], windows: list[Window], every_s: float,
                summary_lines: list[str]) -> str:
    """The plain-text report: samples, faults, faults by kind, failures, growth sites, verdict."""
    run, rss = report["run"], report["rss"]
    lines = [f"# soak: {run['command']}", f"# {run['station']}; {run['schedule']}; {run['load']}", ""]
    lines += _sample_rows(samples, every_s) + [""]
    if len(windows) > 1:
        lines += ["## faults (injected -> what the results and counters show)", *_fault_rows(windows), ""]
        lines += ["| kind | injected | accounted | with problems | crashes | fail-safe trips | trip failures | "
                  "operator re-arms |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
        lines += [f"| {k} | {v['injected']} | {v['accounted']} | {v['problems']} | {v['crashes']} | "
                  f"{v['failsafe_trips']} | {v['trip_failures']} | {v['operator_rearms']} |"
                  for k, v in sorted(report["by_kind"].items())] + [""]
    for name, entries in report["failures"].items():
        lines += [f"{name.replace('_', ' ')}: {len(entries)}"] + [f"  - {e}" for e in entries[:20]]
    if report["growth_sites"] is not None:
        lines += ["", "## growing allocation sites (tracemalloc, warm-up -> end)", "| site | grew KiB | blocks | "
                  "KiB/min | bytes/result |", "|---|---:|---:|---:|---:|"]
        lines += [f"| {s['where']} | {s['grew_kib']:.1f} | {s['blocks']:+d} | {s['kib_per_min']:.1f} | "
                  f"{s['bytes_per_result']:.0f} |" for s in report["growth_sites"]]
    traced = "" if rss["traced_slope_mb_per_min"] is None else \
        f"; traced Python memory {rss['traced_slope_mb_per_min']:+.3f} MB/min"
    lines += ["", "## verdict", _rss_line(rss, "judged") + traced,
              *([_rss_line(report["rss_instant"], "reported")] if report.get("rss_instant") else []),
              f"faults: {sum(not f['skipped'] for f in report['faults'])} injected "
              f"({sum(bool(f['skipped']) for f in report['faults'])} skipped while a station started), "
              f"{len(report['unaccounted'])} unaccounted {report['unaccounted'] or ''}".rstrip(),
              f"unhandled exceptions: {report['unhandled_exceptions']}; station failures: "
              f"{report['station_failures']}",
              f"PLC watchdog trips (after the first command): {report['failsafe_trips']} fail-safe, "
              f"{report['trip_failures']} FAILURE; {_rearm_text(run)}; station rebuilds: {run['restarts']}",
              f"UNSAFE commands (sent while the PLC was not scanning or the e-stop was pressed): "
              f"{report['unsafe_commands']}",
              f"results: {run['results']} ({run['valid']} valid) in {run['elapsed_s']:.1f} s: "
              f"{run['results_per_s']:.2f}/s", *summary_lines,
              "targets: " + ", ".join(f"{k} {'met' if v else 'MISSED'}" for k, v in report["targets"].items())]
    return "\n".join(lines) + "\n"
