"""A prompt stop whatever the devices are doing, and counts that never stop the station.

The stop event is seen within one wait slice; a 10 s settle time (the configuration's limit) is
cut short; no thread raises after the stop. A count that does not add up makes the result invalid,
with the reason, logged at ERROR; the station goes on.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace

from station.faults.harness import fault_config

from wavestack.station import CycleRecord

_STOP_BUDGET_S = 1.0 + 2.0 + 2.0  # one slice and one device exchange (camera timeout 2 s), and a loaded machine


def _run_in_thread(station, stop: threading.Event, records: list[CycleRecord]) -> threading.Thread:
    thread = threading.Thread(target=lambda: station.run(stop=stop, on_result=records.append), name="station-run")
    thread.start()
    return thread


def _stop_and_time(stop: threading.Event, thread: threading.Thread, station) -> float:
    """Stop a running station and close it; the seconds that took."""
    started = time.monotonic()
    stop.set()
    thread.join(timeout=30.0)
    station.close()
    return time.monotonic() - started


def test_stop_is_prompt_with_a_ten_second_settle_time(station_factory, thread_errors) -> None:
    config = fault_config()
    config = replace(config, pzt=replace(config.pzt, settle_s=10.0))
    station, devices = station_factory(config)
    stop, records = threading.Event(), []
    thread = _run_in_thread(station, stop, records)
    try:
        assert _wait_for(lambda: any(c.startswith("xvoltage=") for c in devices.bench.piezo.commands), 10.0)
        time.sleep(0.3)  # inside the first settle wait
        took = _stop_and_time(stop, thread, station)
    finally:
        stop.set()
        thread.join()
    assert took < _STOP_BUDGET_S, took
    assert not any(t.name == "phase-step-acquisition" and t.is_alive() for t in threading.enumerate())


def test_stop_is_prompt_while_a_camera_is_away(station_factory, thread_errors) -> None:
    station, devices = station_factory(fault_config(reconnect_max_s=30.0))
    stop, records = threading.Event(), []
    camera = devices.bench.camera
    thread = _run_in_thread(station, stop, records)
    try:
        assert _wait_for(lambda: any(r.result.valid for r in records), 30.0)
        camera.unplug()
        assert _wait_for(lambda: sum(not r.result.valid for r in records) >= 4, 30.0)  # backing off longer
        took = _stop_and_time(stop, thread, station)
    finally:
        stop.set()
        thread.join()
        camera.replug()
    assert took < _STOP_BUDGET_S, took


def test_counts_that_do_not_add_up_make_an_invalid_result_not_a_dead_station(station_factory, caplog) -> None:
    """A miscount (here a source whose counts break once) is an invalid result with the reason, at ERROR."""
    station, _ = station_factory(fault_config())
    records: list[CycleRecord] = []
    broken = {"left": 1}

    def on_result(record: CycleRecord) -> None:
        records.append(record)
        if len(records) == 3:
            source = station._source
            counters = source.counters

            def counts_once_wrong():
                if broken["left"]:
                    broken["left"] -= 1
                    raise ValueError("phase-step counters: 7 frames in assembly; expected 0..5")
                return counters()

            source.counters = counts_once_wrong

    with caplog.at_level(logging.ERROR, logger="wavestack.station.station"):
        summary = station.run(stop=threading.Event(), on_result=on_result, max_results=6)
    results = [r.result for r in records]
    assert summary.results == 6 and results[-1].valid
    bad = [r for r in results if r.reason and r.reason.startswith("counters:")]
    assert len(bad) == 1 and not bad[0].valid and "expected 0..5" in bad[0].reason
    assert bad[0].output is None or not bad[0].output.command.sent
    assert bad[0].counters == results[bad[0].index - 1].counters  # the last consistent counts, not a wrong one
    assert any("do not add up" in m for m in caplog.messages)


def _wait_for(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True
