"""Jobs, host side: the job and machine blocks (round trips against the simulator's own words), the
allow-list, job limits, the job-id ledger and the job file (against the simulator's own reader)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.plc import (WORD_ORDERS, JobAction, JobFile, JobLimits, JobReason, JobRefused, MachineState,
                                   MachineStatus, RegisterMap, WriteRefused, decode_machine, job_file_name, used_job_ids,
                                   write_job_file)
from wavestack.drivers.plc.jobs import JobLedger, JobSummary
from wavestack.simulators.plc import StopReason, read_job_file
from wavestack.simulators.plc.words import uint32_to_words, words_to_float, words_to_uint32

uint32 = st.integers(0, 2**32 - 1)


def build(order: str = "CDAB", **overrides: object) -> RegisterMap:
    values: dict[str, object] = dict(unit_id=1, word_order=order, self_check_register=0, self_check_value=12345.678,
                                     heartbeat_register=10, rearm_register=11, status_register=20,
                                     command_block=(100, 10), output_block=(200, 10), job_register=300,
                                     machine_register=320)
    values.update(overrides)
    return RegisterMap.build(**values)  # type: ignore[arg-type]


@fuzz_settings(200)
@given(order=st.sampled_from(WORD_ORDERS), action=st.sampled_from(list(JobAction)), job_id=st.integers(1, 65535),
       crc=uint32, count=uint32, dwell=st.floats(0, 1e7, allow_nan=False))
def test_the_job_block_decodes_with_the_simulators_own_words(order: str, action: JobAction, job_id: int, crc: int,
                                                             count: int, dwell: float) -> None:
    registers = build(order).encode_job(action, job_id, crc, count, dwell)
    assert len(registers) == 8 and all(0 <= r <= 0xFFFF for r in registers)
    assert registers[:2] == [int(action), job_id]
    assert words_to_uint32(registers[2:4], order) == crc and words_to_uint32(registers[4:6], order) == count
    assert words_to_float(registers[6:8], order) == pytest.approx(dwell, rel=2**-23)  # float32 rounding


@fuzz_settings(200)
@given(order=st.sampled_from(WORD_ORDERS), state=st.sampled_from(list(MachineState)),
       reason=st.sampled_from(list(JobReason)), job_id=st.integers(0, 65535), done=uint32, count=uint32)
def test_the_machine_block_round_trips(order: str, state: MachineState, reason: JobReason, job_id: int, done: int,
                                       count: int) -> None:
    registers = [int(state), int(reason), job_id, *uint32_to_words(done, order), *uint32_to_words(count, order)]
    status = decode_machine(registers, order)  # type: ignore[arg-type]
    assert (status.state, status.reason, status.job_id, status.points_done, status.point_count) == (
        state, reason, job_id, done, count)


def test_the_reason_codes_agree_with_the_simulators_table() -> None:
    assert [(r.name, int(r)) for r in JobReason] == [(r.name, int(r)) for r in StopReason]
    assert all(r.meaning for r in JobReason)


@pytest.mark.parametrize("registers", [[7, 0, 1, 0, 0, 0, 0], [0, 99, 1, 0, 0, 0, 0], [0, 0, 0]])
def test_unknown_codes_and_wrong_lengths_are_refused(registers: list[int]) -> None:
    with pytest.raises(ValueError, match="unknown|registers"):
        decode_machine(registers, "ABCD")


def test_the_job_block_is_written_whole_and_the_machine_block_never() -> None:
    register_map = build()
    assert register_map.check_write(300, 8, 16).name == "job"
    with pytest.raises(WriteRefused, match="written whole"):
        register_map.check_write(300, 2, 16)
    with pytest.raises(WriteRefused, match="may write only"):
        register_map.check_write(320, 7, 16)
    assert [b.name for b in register_map.blocks() if b.writable] == ["heartbeat", "rearm", "command", "job"]
    assert register_map.markdown_table().count("\n") == 1 + 8


@pytest.mark.parametrize(("overrides", "message"), [
    (dict(machine_register=None), "both or neither"),
    (dict(job_register=105), "overlaps"),
    (dict(machine_register=303), "overlaps"),
])
def test_inconsistent_job_blocks_are_refused(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build(**overrides)


def test_a_map_without_jobs_cannot_encode_one() -> None:
    with pytest.raises(ValueError, match="no job block"):
        build(job_register=None, machine_register=None).encode_job(JobAction.LOAD, 1, 0, 1, 1.0)


LIMITS = JobLimits(100, 60.0, 2.0, 50.0, (-20.0, 20.0), (-10.0, 10.0))


def summary(**changes: object) -> JobSummary:
    values: dict[str, object] = dict(job_id=1, point_count=10, total_dwell_s=10.0, max_dwell_s=1.5, min_dwell_s=0.0,
                                     max_feed_mm_s=30.0, min_feed_mm_s=5.0, x_range_mm=(-5.0, 5.0),
                                     y_range_mm=(-5.0, 5.0))
    values.update(changes)
    return JobSummary(**values)  # type: ignore[arg-type]


@pytest.mark.parametrize(("changes", "message"), [
    (dict(point_count=101), "101 points"), (dict(total_dwell_s=61.0), "max_total_dwell_s"),
    (dict(total_dwell_s=float("nan")), "total dwell"), (dict(min_dwell_s=-0.1), "negative dwell"),
    (dict(max_dwell_s=2.5), "max_dwell_per_point_s"), (dict(min_feed_mm_s=0.0), "feed rate of 0"),
    (dict(max_feed_mm_s=51.0), "max_feed_mm_s"), (dict(x_range_mm=(-21.0, 0.0)), "x from -21"),
    (dict(y_range_mm=(0.0, 10.5)), "y from 0 to 10.5"),
])
def test_each_job_limit_names_the_value_and_the_limit(changes: dict[str, object], message: str) -> None:
    assert LIMITS.violation(summary()) is None
    why = LIMITS.violation(summary(**changes))
    assert why is not None and message in why


@fuzz_settings(200)
@given(st.lists(st.tuples(st.sampled_from(["saw", "refused", "use", "next"]), st.sampled_from(list(MachineState)),
                          st.sampled_from(list(JobReason)), st.integers(0, 65535)), max_size=40))
def test_the_ledger_never_hands_out_a_spent_id_and_only_the_host_moves_it_on(
        steps: list[tuple[str, MachineState, JobReason, int]]) -> None:
    ledger, spent, own = JobLedger(), set(), 0
    for kind, state, reason, job_id in steps:
        status = MachineStatus(state, reason, job_id, 0, 0)
        if kind == "saw":
            ledger.saw(status)
            if state in (MachineState.LOADED, MachineState.RUNNING, MachineState.DONE, MachineState.ABORTED):
                spent.add(job_id)
        elif kind == "refused":
            ledger.refused(status)
            if reason is JobReason.JOB_ID_USED:
                spent.add(job_id)
        elif kind == "use" and job_id >= 1:
            ledger.use(job_id)
            spent.add(job_id)
            own = max(own, job_id)
        else:
            expected = next((i for i in range(own + 1, 65536) if i not in spent), None)
            try:
                fresh = ledger.next_id()
            except JobRefused:
                assert expected is None
                continue
            assert fresh == expected and not ledger.used(fresh)  # the first after the host's own, not spent
            ledger.use(fresh)
            spent.add(fresh)
            own = fresh


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=False)


@fuzz_settings(100)
@given(data=st.data(), n=st.integers(1, 30))
def test_the_job_file_round_trips_through_the_simulators_reader(tmp_path_factory: pytest.TempPathFactory,
                                                               data: st.DataObject, n: int) -> None:
    folder = tmp_path_factory.mktemp("jobs")
    column = st.lists(finite, min_size=n, max_size=n)
    dwell = data.draw(st.lists(st.floats(0, 1e3, allow_nan=False), min_size=n, max_size=n))
    feed = data.draw(st.lists(st.floats(1e-3, 1e3, allow_nan=False), min_size=n, max_size=n))
    job = JobFile(data.draw(st.integers(1, 65535)), np.array(data.draw(column)), np.array(data.draw(column)),
                  np.array(dwell), np.array(feed), 0.05, {"kind": "gaussian", "fwhm_mm": 3.0}, {"pixels": 12})
    receipt = write_job_file(folder, job)
    read = read_job_file(receipt.path, 10**8)
    assert (read.job_id, read.crc32, read.point_count) == (job.job_id, receipt.crc32, job.point_count)
    for name in ("x_mm", "y_mm", "dwell_s", "feed_mm_s"):  # repr round trip: exact
        np.testing.assert_array_equal(getattr(read, name), getattr(job, name))
    assert read.total_dwell_s == receipt.total_dwell_s == job.total_dwell_s
    assert sorted(p.name for p in folder.iterdir()) == [job_file_name(job.job_id)]  # no temporary left


def test_a_job_file_is_never_overwritten_and_its_id_is_found_again(tmp_path: Path) -> None:
    job = JobFile(9, np.zeros(2), np.zeros(2), np.ones(2), np.ones(2), 0.1, {}, {})
    write_job_file(tmp_path, job)
    with pytest.raises(JobRefused, match="used before"):
        write_job_file(tmp_path, job)
    assert used_job_ids(tmp_path) == {9} and used_job_ids(tmp_path / "missing") == set()


@pytest.mark.parametrize(("changes", "message"), [
    (dict(job_id=0), "job_id"), (dict(dwell_s=np.array([1.0, -1.0])), "dwell_s must be >= 0"),
    (dict(feed_mm_s=np.array([1.0, 0.0])), "feed_mm_s must be > 0"), (dict(x_mm=np.zeros(3)), "one length"),
    (dict(y_mm=np.array([0.0, np.inf])), "finite"), (dict(tif={"f": float("nan")}), "plain JSON"),
    (dict(pixel_mm=0.0), "pixel_mm"),
])
def test_a_bad_job_is_refused_naming_the_field(changes: dict[str, object], message: str) -> None:
    values: dict[str, object] = dict(job_id=1, x_mm=np.zeros(2), y_mm=np.zeros(2), dwell_s=np.ones(2),
                                     feed_mm_s=np.ones(2), pixel_mm=0.1, tif={}, aperture={})
    values.update(changes)
    with pytest.raises(ValueError, match=message):
        JobFile(**values)  # type: ignore[arg-type]


def test_a_raw_write_into_the_job_block_is_refused_before_the_wire() -> None:
    from wavestack.drivers.plc import PolishingLink

    link = PolishingLink("127.0.0.1", 9, build())  # nothing listens there: a refusal must come first
    with pytest.raises(WriteRefused, match="job block is written only by"):
        link.write_registers(300, [1, 1, 0, 0, 0, 1, 0, 0], timeout_s=0.5)
    assert not link.connected
