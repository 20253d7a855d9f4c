"""The simulated machine without a server: its job life as data, its own file reader under fuzzing,
its checks (each reason code), its tool's errors."""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.simulators.plc import (GaussianTool, JobEvent, JobFileRefused, JobState, MachineSimSettings,
                                      MachineSnapshot, PolishingMachine, StopReason, next_state, read_job_file)

# What the README's table says, written out again (not derived from the module's table).
EXPECTED = {
    JobEvent.LOAD: {JobState.IDLE: JobState.LOADING, JobState.LOADED: JobState.LOADING,
                    JobState.DONE: JobState.LOADING, JobState.ABORTED: JobState.LOADING,
                    JobState.FAULT: JobState.LOADING},
    JobEvent.LOAD_OK: {JobState.LOADING: JobState.LOADED},
    JobEvent.LOAD_REFUSED: {JobState.LOADING: JobState.FAULT},
    JobEvent.START: {JobState.LOADED: JobState.RUNNING},
    JobEvent.FINISH: {JobState.RUNNING: JobState.DONE},
    JobEvent.STOP: {JobState.RUNNING: JobState.ABORTED, JobState.LOADED: JobState.ABORTED,
                    JobState.LOADING: JobState.ABORTED},
}


@pytest.mark.parametrize("state", list(JobState))
@pytest.mark.parametrize("event", list(JobEvent))
def test_every_state_and_event(state: JobState, event: JobEvent) -> None:
    assert next_state(state, event) is EXPECTED[event].get(state)


def test_a_running_job_is_left_only_by_finish_or_stop() -> None:
    leaving = {e for e in JobEvent if next_state(JobState.RUNNING, e) not in (None, JobState.RUNNING)}
    assert leaving == {JobEvent.FINISH, JobEvent.STOP}
    assert {s for s in JobState if next_state(s, JobEvent.START) is JobState.RUNNING} == {JobState.LOADED}


def settled(m: PolishingMachine, timeout_s: float = 10.0) -> MachineSnapshot:
    """The machine once its load has settled (the loader thread is done): LOADED or FAULT."""
    assert m.wait_idle(timeout_s)
    return m.snapshot()


def job_bytes(job_id: int = 3, points: list[list[float]] | None = None, **header: object) -> bytes:
    rows = points if points is not None else [[0.0, 0.0, 1.0, 10.0], [0.5, 0.0, 2.0, 10.0]]
    document = {"format": "wavestack-polishing-job", "version": 1, "job_id": job_id, "point_count": len(rows),
                "total_dwell_s": 3.0, "columns": ["x_mm", "y_mm", "dwell_s", "feed_mm_s"],
                "points": rows}
    document.update(header)
    if points is not None and "total_dwell_s" not in header:
        document["total_dwell_s"] = float(sum(r[2] for r in rows)) if all(abs(r[2]) < 1e300 for r in rows) else 1.0
    body = json.dumps(document).encode()
    return body + f"\nwsjob-crc32 {zlib.crc32(body):08x} {len(body)}\n".encode()


@fuzz_settings(300)
@given(data=st.data())
def test_the_reader_refuses_any_damaged_file_and_never_raises_anything_else(
        tmp_path_factory: pytest.TempPathFactory, data: st.DataObject) -> None:
    original = job_bytes()
    kind = data.draw(st.sampled_from(["truncate", "flip", "splice", "random"]))
    if kind == "truncate":
        damaged = original[:data.draw(st.integers(0, len(original) - 1))]
    elif kind == "flip":
        at = data.draw(st.integers(0, len(original) - 1))
        damaged = original[:at] + bytes([original[at] ^ data.draw(st.integers(1, 255))]) + original[at + 1:]
    elif kind == "splice":
        at = data.draw(st.integers(0, len(original)))
        damaged = original[:at] + data.draw(st.binary(min_size=1, max_size=20)) + original[at:]
    else:
        damaged = data.draw(st.binary(max_size=400))
    path = tmp_path_factory.mktemp("fuzz") / "job-00003.wsjob"
    path.write_bytes(damaged)
    try:
        job = read_job_file(path, 10**6)
    except JobFileRefused as refusal:
        assert refusal.reason in StopReason and refusal.message
    else:  # only a change the CRC cannot see (none here: every damage above alters the bytes it covers)
        assert job.point_count >= 1 and damaged.endswith(b"\n")


@pytest.mark.parametrize(("data", "reason"), [
    (job_bytes(version=2), StopReason.UNSUPPORTED_FORMAT),
    (job_bytes(point_count=5), StopReason.COUNT_MISMATCH),
    (job_bytes(points=[[0.0, 0.0, True, 1.0]]), StopReason.FILE_CORRUPT),
    (job_bytes(points=[[0.0, 0.0, 10**400, 1.0]]), StopReason.FILE_CORRUPT),
    (job_bytes(job_id="3"), StopReason.FILE_CORRUPT),
    (b"[]\nwsjob-crc32 " + f"{zlib.crc32(b'[]'):08x}".encode() + b" 2\n", StopReason.FILE_CORRUPT),
    (job_bytes() + b"x", StopReason.FILE_TRUNCATED),
])
def test_structural_faults_have_their_reason(tmp_path: Path, data: bytes, reason: StopReason) -> None:
    path = tmp_path / "job-00003.wsjob"
    path.write_bytes(data)
    with pytest.raises(JobFileRefused) as caught:
        read_job_file(path, 10**6)
    assert caught.value.reason is reason


class SumTarget:
    shape = (61, 61)
    pixel_mm = 0.1

    def __init__(self) -> None:
        self.total_nm = 0.0

    def apply_removal(self, removal_nm: np.ndarray) -> None:
        self.total_nm += float(removal_nm.sum())


def machine(folder: Path, target: SumTarget | None = None, **settings: object) -> PolishingMachine:
    values: dict[str, object] = dict(time_scale=1e6, tif_fwhm_mm=0.5, tif_peak_rate_nm_s=4.0,
                                     max_dwell_per_point_s=5.0, max_feed_mm_s=50.0, travel_x_mm=(-2.0, 2.0),
                                     travel_y_mm=(-2.0, 2.0), max_points=10, max_total_dwell_s=20.0)
    values.update(settings)
    return PolishingMachine(MachineSimSettings(folder, **values), target)  # type: ignore[arg-type]


@pytest.mark.parametrize(("rows", "announce", "reason"), [
    ([[0.0, 0.0, 6.0, 1.0]], None, StopReason.DWELL_LIMIT),
    ([[0.0, 0.0, 1.0, 60.0]], None, StopReason.FEED_LIMIT),
    ([[2.5, 0.0, 1.0, 1.0]], None, StopReason.TRAVEL_LIMIT),
    ([[0.0, 0.0, 1.0, 1.0]] * 11, None, StopReason.TOO_MANY_POINTS),
    ([[0.0, 0.0, 4.0, 1.0]] * 6, None, StopReason.TOTAL_DWELL_LIMIT),
    ([[0.0, 0.0, 1.0, 1.0]], dict(crc=1), StopReason.CRC_MISMATCH),
    ([[0.0, 0.0, 1.0, 1.0]], dict(count=2), StopReason.COUNT_MISMATCH),
    ([[0.0, 0.0, 1.0, 1.0]], dict(dwell=1.5), StopReason.DWELL_MISMATCH),
])
def test_each_machine_check_refuses_with_its_reason(tmp_path: Path, rows: list[list[float]],
                                                    announce: dict[str, float] | None, reason: StopReason) -> None:
    data = job_bytes(3, rows)
    (tmp_path / "job-00003.wsjob").write_bytes(data)
    body = data[:data.rindex(b"\nwsjob")]
    values = dict(crc=zlib.crc32(body), count=len(rows), dwell=float(sum(r[2] for r in rows)))
    values.update(announce or {})
    m = machine(tmp_path)
    assert m.load(3, int(values["crc"]), int(values["count"]), values["dwell"])
    snapshot = settled(m)
    assert (snapshot.state, snapshot.reason) == (JobState.FAULT, reason)
    assert m.start(3) is False and 3 not in m.used_job_ids


def test_a_retried_load_is_a_no_op_and_an_id_never_runs_twice(tmp_path: Path) -> None:
    data = job_bytes(3)
    (tmp_path / "job-00003.wsjob").write_bytes(data)
    crc = zlib.crc32(data[:data.rindex(b"\nwsjob")])
    m = machine(tmp_path, SumTarget())
    assert m.load(3, crc, 2, 3.0) and m.load(3, crc, 2, 3.0)  # the second while loading, or loaded: a retry
    assert settled(m).state is JobState.LOADED
    assert m.load(3, crc, 2, 3.0) and m.snapshot().state is JobState.LOADED
    assert m.start(4) is False and m.start(3) and m.start(3)  # a retried start: the same run
    assert m.wait_idle(10.0)
    assert m.snapshot().state is JobState.DONE
    assert m.load(3, crc, 2, 3.0) and m.snapshot().reason is StopReason.JOB_ID_USED


@pytest.mark.parametrize(("width_error", "rate_error"), [(0.0, 0.1), (0.2, 0.0), (-0.1, -0.3)])
def test_the_tool_errors_scale_the_removed_volume(tmp_path: Path, width_error: float, rate_error: float) -> None:
    data = job_bytes(3, [[0.0, 0.0, 2.0, 10.0], [0.5, 0.5, 1.0, 10.0]])
    (tmp_path / "job-00003.wsjob").write_bytes(data)
    target = SumTarget()
    m = machine(tmp_path, target, width_error=width_error, rate_error=rate_error)
    m.load(3, zlib.crc32(data[:data.rindex(b"\nwsjob")]), 2, 3.0)
    settled(m)
    m.start(3)
    assert m.wait_idle(10.0)
    # volume = dwell x 2 pi sigma^2 x peak: (1 + width)^2 (1 + rate) times the nominal tool's
    nominal = 3.0 * GaussianTool(0.5, 4.0, 0.1).volume_per_second_px()
    assert target.total_nm == pytest.approx(nominal * (1 + width_error) ** 2 * (1 + rate_error), rel=5e-4)


class BrokenTarget(SumTarget):
    def apply_removal(self, removal_nm: np.ndarray) -> None:
        raise OSError("the optic's surface store failed")


def test_a_machine_that_fails_mid_run_ends_aborted_not_running(tmp_path: Path,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    data = job_bytes(3)
    (tmp_path / "job-00003.wsjob").write_bytes(data)
    m = machine(tmp_path, BrokenTarget())
    m.load(3, zlib.crc32(data[:data.rindex(b"\nwsjob")]), 2, 3.0)
    settled(m)
    m.start(3)
    assert m.wait_idle(10.0)
    snapshot = m.snapshot()
    assert (snapshot.state, snapshot.reason) == (JobState.ABORTED, StopReason.MACHINE_FAULT)
    assert "surface store failed" in caplog.text


def test_an_abort_of_a_loaded_job_spends_it_without_polishing(tmp_path: Path) -> None:
    data = job_bytes(3)
    (tmp_path / "job-00003.wsjob").write_bytes(data)
    target = SumTarget()
    m = machine(tmp_path, target)
    m.load(3, zlib.crc32(data[:data.rindex(b"\nwsjob")]), 2, 3.0)
    assert settled(m).state is JobState.LOADED
    assert m.abort(4) is False and m.abort(3)
    snapshot = m.snapshot()
    assert (snapshot.state, snapshot.reason, snapshot.points_done) == (JobState.ABORTED, StopReason.HOST_ABORT, 0)
    assert m.start(3) and target.total_nm == 0  # a start after the abort reports the end, runs nothing
    assert m.wait_idle(0.0)  # no thread was started


@fuzz_settings(200)
@given(writes=st.lists(st.lists(st.integers(0, 0xFFFF), min_size=8, max_size=8), min_size=1, max_size=6))
def test_any_job_block_write_is_answered_and_never_raises(tmp_path_factory: pytest.TempPathFactory,
                                                          writes: list[list[int]]) -> None:
    from wavestack.simulators.plc import PlcSimLayout, PolishingPlcProgram, PolishingStation, SimFaults

    folder = tmp_path_factory.mktemp("jobs")
    (folder / "job-00003.wsjob").write_bytes(job_bytes(3))
    layout = PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=12345.678, self_check_word_order="ABCD",
                          heartbeat_register=10, rearm_register=11, status_register=20, command_block=(100, 4),
                          output_block=(200, 4), command_word_order="ABCD", output_word_order="ABCD",
                          watchdog_timeout_s=60.0, job_register=300, machine_register=320)
    m = machine(folder)
    program = PolishingPlcProgram(layout, PolishingStation((0.0,)), SimFaults(), m)
    memory = [0] * 400
    assert program.on_request(10, [1], 0.0, 0, memory) is None  # a heartbeat: the watchdog runs
    for registers in writes:
        answer = program.on_request(300, registers, 0.1, 0, memory)
        assert answer is None or int(answer) in (3, 4, 6)
        assert 0 <= memory[320] <= 6 and 0 <= memory[321] <= 19  # the machine block holds a known state and reason
    m.close()
