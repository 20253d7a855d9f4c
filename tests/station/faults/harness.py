"""The live-station fault harness: a fault injected through a simulator's own switch, what to check after.

:func:`run_fault` runs a station until it has produced valid results again after the fault
cleared (or a deadline), recording every result, the PLC watchdog's trips and any exception that
escaped a thread. :func:`check_fault_run` asserts what every fault test asserts.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

from wavestack.config import StationConfig, load_station_config
from wavestack.station import CycleRecord

SMALL = Path(__file__).resolve().parents[2] / "configs" / "station-small.toml"


WATCHDOG_S = 1.5
FRAME_TIMEOUT_S = 3.0


def fault_config(method: str = "psi", **station: object) -> StationConfig:
    """The small station with a PLC watchdog (1.5 s) shorter than ``frame_timeout_s`` (3 s).

    A camera stall shorter than ``frame_timeout_s`` must then not trip the watchdog: only a loop
    that keeps the heartbeat alive while it waits passes.
    """
    config = load_station_config(SMALL)
    settings = {"max_result_age_s": 20.0, "frame_timeout_s": FRAME_TIMEOUT_S, **station}
    # a qr fitter: no background map build (seconds of CPU) competing with the faults
    config = replace(config, processing=replace(config.processing, method=method, fit_method="qr"),
                     plc=replace(config.plc, link=replace(config.plc.link, watchdog_timeout_s=WATCHDOG_S)),
                     # a loaded machine must not make results stale: this suite is about faults
                     station=replace(config.station, **settings))
    if method == "carrier":
        config = replace(config, optic=replace(config.optic, carrier_cycles=(30.0, 18.0)))
    return config


@dataclass
class FaultRun:
    """What a run with one fault produced."""

    records: list[CycleRecord] = field(default_factory=list)
    injected_at: int | None = None  # index of the first result after the fault was injected
    cleared_at: int | None = None  # index of the first result after it cleared
    trips_at_injection: int = 0
    trips_at_clear: int = 0  # the watchdog's trips while the fault lasted: trips_at_clear - trips_at_injection
    summary: object = None

    def during(self) -> list[CycleRecord]:
        assert self.injected_at is not None and self.cleared_at is not None
        return self.records[self.injected_at:self.cleared_at]

    def after(self) -> list[CycleRecord]:
        assert self.cleared_at is not None
        return self.records[self.cleared_at:]


def run_fault(station, devices, *, inject: Callable[[], None], clear: Callable[[], None] | None = None,
              hold_s: float = 0.0, warm_up: int = 3, valid_after: int = 3, max_s: float = 45.0) -> FaultRun:
    """Run ``station`` with a fault: ``inject`` after ``warm_up`` valid results, ``clear`` ``hold_s`` later.

    Without ``clear`` the fault is one-shot (cleared at once). Stops once ``valid_after`` valid
    results came after the clear, or after ``max_s``.
    """
    run, stop, lock = FaultRun(), threading.Event(), threading.Lock()
    plc = devices.plc_simulator
    timer: threading.Timer | None = None

    def do_clear() -> None:
        if clear is not None:
            clear()
        run.trips_at_clear = plc.watchdog_trips if plc is not None else 0
        with lock:
            run.cleared_at = len(run.records)

    def on_result(record: CycleRecord) -> None:
        nonlocal timer
        with lock:
            run.records.append(record)
            # warm: valid results, and the fitter built (its background build loads the machine)
            valid = sum(r.result.valid and not r.result.fitter_fallback for r in run.records)
            inject_now = run.injected_at is None and valid >= warm_up
            cleared_at = run.cleared_at
        if inject_now:
            run.trips_at_injection = plc.watchdog_trips if plc is not None else 0
            inject()
            with lock:
                run.injected_at = len(run.records)
            if clear is None:
                do_clear()
            else:
                timer = threading.Timer(hold_s, do_clear)
                timer.start()
        elif cleared_at is not None and sum(r.result.valid for r in run.records[cleared_at:]) >= valid_after:
            stop.set()

    try:
        run.summary = station.run(stop=stop, on_result=on_result, duration_s=max_s)
    finally:
        if timer is not None:
            timer.cancel()
            timer.join()
            if run.cleared_at is None:
                do_clear()
    return run


def check_fault_run(run: FaultRun, check_counts, frames_per_set: int, *, watchdog: bool = True) -> None:
    """What every fault run must show (see the module notes of the fault tests)."""
    assert run.injected_at is not None, "the station never produced the warm-up results"
    assert run.cleared_at is not None
    results = [r.result for r in run.records]
    # the station survived and produces valid results again
    assert sum(r.valid for r in results[run.cleared_at:]) >= 3, [r.reason for r in results[run.injected_at:]]
    # an invalid result always says why, and is never sent to the PLC
    for r in results:
        if not r.valid:
            assert r.reason, r
            assert r.output is None or not r.output.command.sent, r
    # counters add up at every result and only grow, across reconnects
    last = check_counts(run.records, frames_per_set, ids_from_zero=False)
    c = run.summary.counters
    assert c.frames.acquired == c.frames.processed + c.frames.dropped + c.frames.pending
    assert c.frames.acquired >= last.frames.acquired and c.sets.processed == last.sets.processed
    if watchdog:  # the host stayed healthy while the device was faulty: the watchdog must not trip
        assert run.trips_at_clear == run.trips_at_injection, (run.trips_at_injection, run.trips_at_clear)
