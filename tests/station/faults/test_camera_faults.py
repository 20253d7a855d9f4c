"""Camera faults against the live station, injected through the simulated camera's own switches.

Each test asserts (:func:`check_fault_run`): the station survives and produces valid results again
after the fault clears, an invalid result says why and is never sent, the counters add up at
every result and only grow (across reconnects), no exception escapes a thread, and the PLC's
watchdog (1.5 s here, shorter than ``frame_timeout_s`` = 3 s) does not trip while the fault lasts: a
device fault is not a host fault, so the loop keeps the heartbeat alive while it waits. (One-shot
faults have no such window; a pipeline slowed by a loaded machine may rightly trip it.)
"""

from __future__ import annotations

import gc
import threading
import weakref

import pytest
from station.faults.harness import check_fault_run, fault_config, run_fault

from wavestack.station.station import Station


def _lost(run) -> list:
    return [r.result for r in run.records[run.injected_at:] if not r.result.valid]


@pytest.mark.parametrize("hold_s", [0.3, 3.0], ids=["short", "long"])
def test_an_unplugged_camera_comes_back(station_factory, check_counts, thread_errors, hold_s) -> None:
    station, devices = station_factory(fault_config())
    camera = devices.bench.camera
    run = run_fault(station, devices, inject=camera.unplug, clear=camera.replug, hold_s=hold_s)
    check_fault_run(run, check_counts, 5)
    lost = _lost(run)
    assert lost and all(r.reason.startswith("device:") for r in lost), [r.reason for r in lost]


def test_a_flapping_camera_comes_back(station_factory, check_counts, thread_errors) -> None:
    """Unplugged and replugged five times, 0.15 s apart (a loose connector)."""
    station, devices = station_factory(fault_config())
    camera = devices.bench.camera
    done = threading.Event()

    def flap() -> None:
        for _ in range(5):
            camera.unplug()
            if done.wait(0.15):
                break
            camera.replug()
            if done.wait(0.15):
                break
        camera.replug()

    flapper = threading.Thread(target=flap, name="flapper")
    try:
        run = run_fault(station, devices, inject=flapper.start, clear=lambda: flapper.join(), hold_s=1.6)
    finally:
        done.set()
        if flapper.is_alive():
            flapper.join()
    check_fault_run(run, check_counts, 5)
    assert _lost(run)


@pytest.mark.parametrize("method", ["psi", "carrier"])
@pytest.mark.parametrize("fault", ["corrupt_leader", "corrupt_trailer", "partial_transfer"])
def test_a_damaged_block_costs_one_set_not_a_timeout(station_factory, check_counts, thread_errors,
                                                     fault, method) -> None:
    """A damaged block is dropped (counted); in phase-shifting mode the set it belonged to is given up at
    once, not after a frame timeout, so no result reports a lost device."""
    station, devices = station_factory(fault_config(method))
    camera = devices.bench.camera
    value = {"corrupt_leader": "magic", "corrupt_trailer": "block_id", "partial_transfer": True}[fault]
    run = run_fault(station, devices, inject=lambda: setattr(camera.faults, fault, value))
    check_fault_run(run, check_counts, 5 if method == "psi" else 1, watchdog=False)  # one-shot: no window
    assert not _lost(run), [r.reason for r in _lost(run)]
    assert getattr(camera.faults, fault) in (None, False)  # the fault did happen
    before = run.records[run.injected_at - 1].result.counters
    assert run.summary.counters.frames.dropped > before.frames.dropped


@pytest.mark.parametrize("method", ["psi", "carrier"])
def test_a_stream_stall_shorter_than_the_frame_timeout_keeps_the_plc_alive(station_factory, check_counts,
                                                                           thread_errors, method) -> None:
    """2 s without a frame (frame_timeout_s = 3 s, watchdog 1.5 s): no lost device, no watchdog trip."""
    station, devices = station_factory(fault_config(method))
    faults = devices.bench.camera.faults

    def clear() -> None:
        faults.stream_paused = False

    run = run_fault(station, devices, inject=lambda: setattr(faults, "stream_paused", True), clear=clear,
                    hold_s=2.0)
    check_fault_run(run, check_counts, 5 if method == "psi" else 1)
    assert not _lost(run), [r.reason for r in _lost(run)]


def test_a_stall_longer_than_the_frame_timeout_gives_invalid_results_and_keeps_the_plc_alive(
        station_factory, check_counts, thread_errors) -> None:
    station, devices = station_factory(fault_config())
    faults = devices.bench.camera.faults

    def clear() -> None:
        faults.stream_paused = False

    run = run_fault(station, devices, inject=lambda: setattr(faults, "stream_paused", True), clear=clear,
                    hold_s=4.0)
    check_fault_run(run, check_counts, 5)
    lost = _lost(run)
    assert lost and all(r.reason.startswith("device:") for r in lost), [r.reason for r in lost]


@pytest.mark.parametrize("fault, value", [("stall_next", True), ("timeout_reads", 5)])
def test_an_endpoint_stall_or_read_timeouts_are_survived(station_factory, check_counts, thread_errors,
                                                         fault, value) -> None:
    station, devices = station_factory(fault_config())
    faults = devices.bench.camera.faults
    run = run_fault(station, devices, inject=lambda: setattr(faults, fault, value))
    check_fault_run(run, check_counts, 5, watchdog=False)  # one-shot: no window


def _acquisition_threads() -> dict[str, list[threading.Thread]]:
    roles = ("u3v-reader", "phase-step-acquisition")
    return {role: [t for t in threading.enumerate() if t.name.startswith(role) and t.is_alive()] for role in roles}


def test_a_reconnect_frees_the_lost_source_and_keeps_the_acquisition_threads(station_factory, check_counts,
                                                                             thread_errors, monkeypatch) -> None:
    """With the cyclic GC off, a retired phase-step source (its ring of sets, the half-read set) is gone by
    reference counting alone before the station makes the next source, and the camera's reader and the
    stepping run on the same two threads after the reconnect (issue 13's soak: the sets of the lost source
    stayed alive, in a cycle through the error kept in its ring and, until the except block ended, through
    the raised error's traceback, while the new source filled its own; and new threads, new malloc arenas,
    moved RSS at each reconnect)."""
    made: list[weakref.ref] = []
    alive_when_made: list[int] = []
    original = Station._make_source

    def make_source(self):
        alive_when_made.append(sum(ref() is not None for ref in made))
        source = original(self)
        made.append(weakref.ref(source))
        return source

    monkeypatch.setattr(Station, "_make_source", make_source)
    station, devices = station_factory(fault_config())
    camera = devices.bench.camera
    before: dict[str, list[threading.Thread]] = {}

    def unplug() -> None:
        before.update(_acquisition_threads())
        camera.unplug()

    gc.disable()  # only reference counting frees: what a cycle holds stays
    try:
        run = run_fault(station, devices, inject=unplug, clear=camera.replug, hold_s=0.3)
    finally:
        gc.enable()
    check_fault_run(run, check_counts, 5)
    assert len(made) >= 2, "the station never made a new source after the unplug"
    assert alive_when_made == [0] * len(made), alive_when_made
    after = _acquisition_threads()
    assert all(len(threads) == 1 for threads in before.values()), before
    assert after == before, (before, after)
