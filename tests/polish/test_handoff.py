"""Waiting for the machine: every way the wait ends, against a scripted machine (no sleeps: poll_s = 0)."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from types import SimpleNamespace

import pytest

from wavestack.drivers.errors import DeviceDisconnected
from wavestack.drivers.plc import PlcRefused
from wavestack.polish.handoff import state_name, wait_for_done
from wavestack.station import Heartbeat


def _state(name: str) -> SimpleNamespace:
    return SimpleNamespace(name=name)


@dataclass
class ScriptedMachine:
    """Answers read_machine from a script: (state, reason, job id, points done) or an exception; the last repeats."""

    script: list

    def read_machine(self, timeout_s: float):
        step = self.script.pop(0) if len(self.script) > 1 else self.script[0]
        if isinstance(step, Exception):
            raise step
        state, reason, job_id, done = step
        return SimpleNamespace(state=_state(state), reason=_state(reason), job_id=job_id, points_done=done,
                               point_count=100)


def _wait(script, *, heartbeat=None, stop=None, timeout_s=30.0, grace_s=1e9):
    return wait_for_done(ScriptedMachine(script), 7, timeout_s=timeout_s, poll_s=0.0, io_timeout_s=0.1,
                         stop=stop or threading.Event(), heartbeat=heartbeat or (lambda: None),
                         start_grace_s=grace_s, refused_wait_s=0.0)


def test_done_after_progress_and_a_lost_read() -> None:
    end = _wait([("RUNNING", "NONE", 7, 10), DeviceDisconnected("PLC", "lost"), ("RUNNING", "NONE", 7, 60),
                 ("DONE", "NONE", 7, 100)])
    assert end.done and (end.state, end.points_done, end.point_count) == ("DONE", 100, 100)


@pytest.mark.parametrize("state", ["ABORTED", "FAULT"])
def test_aborted_or_fault_ends_with_the_reason(state: str) -> None:
    end = _wait([("RUNNING", "NONE", 7, 10), (state, "ESTOP", 7, 42)])
    assert not end.done and (end.state, end.reason, end.points_done) == (state, "ESTOP", 42)


def test_a_done_of_another_job_is_not_ours_and_a_lost_job_ends_the_wait() -> None:
    end = _wait([("DONE", "NONE", 6, 100)], grace_s=0.0)
    assert not end.done and (end.state, end.reason) == ("LOST", "DONE") and "not running job 7" in end.detail


def test_a_tripped_watchdog_or_refused_reads_end_the_wait() -> None:
    tripped = Heartbeat(ok=False, watchdog_tripped=True)
    end = _wait([("RUNNING", "NONE", 7, 30)], heartbeat=lambda: tripped)
    assert (end.state, end.reason, end.points_done) == ("UNKNOWN", "WATCHDOG", 30)
    end = _wait([("RUNNING", "NONE", 7, 30), PlcRefused("PLC", 3, 320, 4)])
    assert (end.state, end.reason, end.points_done) == ("UNKNOWN", "PLC_REFUSED", 30)


def test_timeout_and_stop() -> None:
    end = _wait([DeviceDisconnected("PLC", "gone")], timeout_s=0.0)
    assert (end.state, end.reason) == ("UNKNOWN", "TIMEOUT") and "gone" in end.detail
    stop = threading.Event()
    stop.set()
    end = _wait([("RUNNING", "NONE", 7, 5)], stop=stop)
    assert (end.reason, end.points_done) == ("STOPPED", 5)


def test_state_name_of_enums_and_text() -> None:
    assert state_name(_state("DONE")) == "DONE" and state_name("x") == "x" and state_name(None) == ""
