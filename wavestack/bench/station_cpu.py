"""CPU and wall-time accounting for ``wavestack bench station``: simulators, PLC link, threads.

The simulated devices' entry points (camera USB backend, optic render, piezo ``feed``) are wrapped
on these instances only to sum their thread CPU time (``time.thread_time``); the PLC link's calls
are wrapped on wall time. Per-thread CPU time (user + system) comes from ``/proc/self/task``, by
thread role. A :class:`_Mark` snapshots all of it at the start and the end of a measured window.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from wavestack.station import StationDevices

F = TypeVar("F", bound=Callable[..., Any])


class _Meter:
    """Time spent inside wrapped callables, summed by key, on ``clock`` (thread CPU or wall time)."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._totals: dict[str, float] = {}

    def wrap(self, key: str, function: F) -> F:
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = self._clock()
            try:
                return function(*args, **kwargs)
            finally:
                spent = self._clock() - start
                with self._lock:
                    self._totals[key] = self._totals.get(key, 0.0) + spent
        return timed  # type: ignore[return-value]

    def snapshot(self) -> dict[str, float]:
        with self._lock:
            return dict(self._totals)


def _instrument(devices: StationDevices, cpu: _Meter, wall: _Meter) -> None:
    """Wrap the simulated devices' entry points (CPU) and the PLC link's calls (wall), these instances only."""
    bench = devices.bench
    assert bench is not None
    backend = bench.backend
    backend.bulk_read = cpu.wrap("camera", backend.bulk_read)  # type: ignore[method-assign]
    backend.bulk_write = cpu.wrap("camera", backend.bulk_write)  # type: ignore[method-assign]
    bench.optic.interferogram = cpu.wrap("render", bench.optic.interferogram)  # type: ignore[method-assign]
    if bench.piezo is not None:
        bench.piezo.feed = cpu.wrap("piezo", bench.piezo.feed)  # type: ignore[method-assign]
    if devices.link is not None:
        for name in ("heartbeat", "send_removal", "read_status", "rearm"):
            setattr(devices.link, name, wall.wrap("plc", getattr(devices.link, name)))


_THREAD_ROLES = (("MainThread", "pipeline"), ("u3v-reader", "camera reader"), ("phase-step", "phase stepping"),
                 ("plc-simulator", "plc"), ("fitter-build", "fitter build"))


def _thread_cpu_s() -> dict[str, float]:
    """CPU seconds (user + system) of every thread of the process by role (Linux ``/proc``; else empty)."""
    ticks = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    roles = {thread.native_id: next((r for prefix, r in _THREAD_ROLES if thread.name.startswith(prefix)), "other")
             for thread in threading.enumerate()}
    found: dict[str, float] = {}
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return found
    for task in tasks:
        try:
            with open(f"/proc/self/task/{task}/stat", "rb") as stat:
                fields = stat.read().rsplit(b")", 1)[1].split()
        except (OSError, IndexError):  # the thread ended meanwhile
            continue
        role = roles.get(int(task), "native pools")
        found[role] = found.get(role, 0.0) + (int(fields[11]) + int(fields[12])) / ticks  # utime, stime
    return found


@dataclass(frozen=True)
class _Mark:
    wall_s: float
    process_s: float
    simulators: dict[str, float]
    threads: dict[str, float]
    io_wall: dict[str, float]
    plc_requests: int


def _mark(devices: StationDevices, cpu: _Meter, wall: _Meter) -> _Mark:
    requests = devices.plc_simulator.request_count if devices.plc_simulator is not None else 0
    return _Mark(time.perf_counter(), time.process_time(), cpu.snapshot(), _thread_cpu_s(), wall.snapshot(), requests)


def _per_result_ms(start: dict[str, float], end: dict[str, float], results: int) -> dict[str, float]:
    return {key: (value - start.get(key, 0.0)) * 1e3 / results for key, value in sorted(end.items())}
