"""The station's sink for the loop: N valid fresh maps in a row, and every way a measurement gives up."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest

from wavestack.station.live_maps import LiveMaps, UntrustedMeasurement, sample_of
from wavestack.station.counters import Counters
from wavestack.station.cycle import CycleRecord
from wavestack.station.plc_status import Heartbeat
from wavestack.station.results import ApertureRecord, OutputRecord, SentCommand, StationResult


def _record(index: int, t_ns: int, *, valid: bool = True, tripped: bool = False) -> CycleRecord:
    result = StationResult.invalid(index, "fit: bad", Counters.zero(5), ordering="noll", exposure_time_ns=t_ns)
    output = OutputRecord(Heartbeat(ok=not tripped, watchdog_tripped=tripped),
                          SentCommand(False, None, "HELD", None, ()))
    if valid:
        result = dataclasses.replace(result, valid=True, reason=None,
                                     aperture=ApertureRecord(0, False, "disk", 16))
    result = dataclasses.replace(result, output=output)
    return CycleRecord(result, waves=np.full((4, 4), float(index)) if valid else None)


def _feed(maps: LiveMaps, records: list[CycleRecord]) -> threading.Thread:
    def run() -> None:
        deadline = time.monotonic() + 10.0
        while not maps.collecting and time.monotonic() < deadline:  # poll with a deadline
            time.sleep(0.001)
        for record in records:
            maps(record)
    thread = threading.Thread(target=run)
    thread.start()
    return thread


def _collect(maps: LiveMaps, records: list[CycleRecord], **kwargs) -> list:
    thread = _feed(maps, records)  # starts feeding once collect() holds its request
    try:
        return maps.collect(**{"count": 3, "max_results": 10, "not_before_ns": 100, "timeout_s": 20.0,
                               "stop": threading.Event(), **kwargs})
    finally:
        thread.join()


def test_collects_valid_fresh_maps_in_a_row() -> None:
    maps = LiveMaps()
    records = [_record(0, 50), _record(1, 150), _record(2, 160, valid=False), _record(3, 170), _record(4, 180),
               _record(5, 190), _record(6, 200)]
    samples = _collect(maps, records)
    # the stale one (exposed before 100) is skipped, the invalid one empties the window
    assert [s.waves[0, 0] for s in samples] == [3.0, 4.0, 5.0]
    assert maps.results == 7


def test_gives_up_after_max_results_naming_the_last_invalid() -> None:
    maps = LiveMaps()
    records = [_record(i, 200 + i, valid=i % 2 == 0) for i in range(12)]
    with pytest.raises(UntrustedMeasurement, match="expected 3 valid results in a row.*last invalid: fit: bad"):
        _collect(maps, records)


def test_gives_up_when_the_station_ends_or_stop_is_set() -> None:
    maps = LiveMaps()
    maps.end("camera lost")
    with pytest.raises(UntrustedMeasurement, match="camera lost"):
        maps.collect(3, max_results=10, not_before_ns=0, timeout_s=5.0, stop=threading.Event())
    stop = threading.Event()
    stop.set()
    with pytest.raises(UntrustedMeasurement, match="stopped"):
        LiveMaps().collect(3, max_results=10, not_before_ns=0, timeout_s=5.0, stop=stop)
    with pytest.raises(UntrustedMeasurement, match="in 0.05 s"):
        LiveMaps().collect(3, max_results=10, not_before_ns=0, timeout_s=0.05, stop=threading.Event())


def test_keeps_the_last_heartbeat_between_measurements() -> None:
    maps = LiveMaps()
    maps(_record(0, 1))
    assert maps.last_heartbeat is not None and not maps.last_heartbeat.watchdog_tripped
    maps(_record(1, 2, valid=False, tripped=True))
    assert maps.last_heartbeat.watchdog_tripped


def test_sample_of_an_invalid_record_is_invalid() -> None:
    sample = sample_of(_record(0, 5, valid=False))
    assert not sample.valid and sample.reason == "fit: bad" and sample.aperture_id is None
