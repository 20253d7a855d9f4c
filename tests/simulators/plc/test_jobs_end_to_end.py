"""Polishing jobs end to end: host writes the file and drives the job over loopback Modbus/TCP, the
simulated machine polishes a test double; faults through the simulator's own switches."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from wavestack.drivers import DeviceDisconnected

from wavestack.drivers.plc import (HeartbeatEchoStale, JobFile, JobLimits, JobNotReady, JobReason, JobRefused, JobRejected, LinkTiming,
                                   MachineState, PolishingLink, RegisterMap, write_job_file)
from wavestack.simulators.plc import (GaussianTool, MachineSimSettings, PlcSimLayout, PlcSimulator, PolishingMachine,
                                      PolishingStation)

TIMING = LinkTiming(io_timeout_s=0.5, reconnect_initial_s=0.02, reconnect_max_s=0.2, command_retries=2,
                    heartbeat_echo_max_lag=2)
LIMITS = JobLimits(10_000, 10_000.0, 20.0, 100.0, (-5.0, 5.0), (-5.0, 5.0))
JOB_REGISTER, MACHINE_REGISTER = 300, 320
WAIT_S = 20.0  # bound on waiting for a state; never a timing assertion


class RecordingTarget:
    """A RemovalTarget double: records every chunk's sum and count."""

    shape = (81, 81)
    pixel_mm = 0.1

    def __init__(self) -> None:
        self.total_nm = 0.0
        self.chunks = 0

    def apply_removal(self, removal_nm: np.ndarray) -> None:
        assert removal_nm.shape == self.shape
        self.total_nm += float(removal_nm.sum())
        self.chunks += 1


def layout(watchdog_timeout_s: float) -> PlcSimLayout:
    return PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=12345.678, self_check_word_order="CDAB",
                        heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20, command_block=(100, 10),
                        output_block=(200, 10), command_word_order="CDAB", output_word_order="CDAB",
                        watchdog_timeout_s=watchdog_timeout_s, job_register=JOB_REGISTER,
                        machine_register=MACHINE_REGISTER)


def register_map() -> RegisterMap:
    return RegisterMap.build(unit_id=1, word_order="CDAB", self_check_register=0, self_check_value=12345.678,
                             heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20, command_block=(100, 10),
                             output_block=(200, 10), job_register=JOB_REGISTER, machine_register=MACHINE_REGISTER)


@contextmanager
def station(folder: Path, *, time_scale: float = 1e4, watchdog_timeout_s: float = 60.0
            ) -> Iterator[tuple[PlcSimulator, PolishingLink, RecordingTarget]]:
    target = RecordingTarget()
    machine = PolishingMachine(MachineSimSettings(folder, time_scale=time_scale, tif_fwhm_mm=0.6,
                                                  tif_peak_rate_nm_s=5.0, travel_x_mm=(-4.0, 4.0),
                                                  travel_y_mm=(-4.0, 4.0), max_dwell_per_point_s=10.0), target)
    with PlcSimulator(layout(watchdog_timeout_s), PolishingStation((0.0, 0.0, 0.0, 0.0)), machine=machine) as sim:
        with PolishingLink("127.0.0.1", sim.port, register_map(), TIMING, job_limits=LIMITS) as link:
            link.connect(timeout_s=2.0)
            link.self_check(timeout_s=1.0)
            link.heartbeat(timeout_s=1.0)
            yield sim, link, target


def make_job(job_id: int, n: int = 40, dwell_s: float = 1.0, x_max_mm: float = 2.0) -> JobFile:
    x = np.linspace(-x_max_mm, x_max_mm, n)
    return JobFile(job_id, x, np.zeros(n), np.full(n, dwell_s), np.full(n, 20.0), 0.1,
                   {"kind": "gaussian", "fwhm_mm": 0.6, "peak_rate_nm_s": 5.0}, {"pixels": 81 * 81})


def wait_for(condition: Callable[[], bool], beat: PolishingLink | None = None) -> bool:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if beat is not None:
            beat.heartbeat(timeout_s=1.0)
        if condition():
            return True
        time.sleep(0.01)
    return condition()


def job_writes(sim: PlcSimulator) -> list[tuple[int, ...]]:
    """The job-block writes the simulator decoded: what reached the wire."""
    return [r.values for r in sim.requests if r.function_code == 16 and r.address == JOB_REGISTER]


def test_a_job_runs_to_done_and_removes_what_the_machine_tool_predicts(tmp_path: Path) -> None:
    with station(tmp_path, time_scale=200.0) as (sim, link, target):
        assert sim.machine is not None
        job_id = link.next_job_id()
        job = make_job(job_id)
        receipt = write_job_file(tmp_path, job)
        assert link.load_job(receipt, job_id).state is MachineState.LOADED
        assert link.start_job(job_id).state in (MachineState.RUNNING, MachineState.DONE)
        progress = [link.read_machine().points_done]
        assert wait_for(lambda: progress.append(link.read_machine().points_done) or
                        link.read_machine().state is MachineState.DONE, beat=link)
        final = link.read_machine()
        assert (final.points_done, final.point_count, final.reason) == (40, 40, JobReason.NONE)
        assert progress == sorted(progress) and len(set(progress)) > 2  # it grew, chunk by chunk
        # With no errors configured, removal = sum(dwell) x the tool's volume rate; every footprint
        # lies on the grid (|x| <= 2 mm + 4 sigma = 2.1 mm < 4 mm); the 4-sigma cut loses < 1.3e-4
        # and the pixel sum equals the integral to 1e-6 (sigma = 2.5 px): 5e-4 is safe.
        tool = GaussianTool(0.6, 5.0, 0.1)
        expected = float(job.dwell_s.sum()) * tool.volume_per_second_px()
        assert target.total_nm == pytest.approx(expected, rel=5e-4)
        assert target.chunks >= 2


def test_estop_mid_run_aborts_keeps_the_partial_removal_and_the_id_is_spent(tmp_path: Path) -> None:
    with station(tmp_path, time_scale=20.0) as (sim, link, target):
        assert sim.machine is not None
        job_id = link.next_job_id()
        job = make_job(job_id, n=100)
        link.load_job(write_job_file(tmp_path, job), job_id)
        link.start_job(job_id)
        assert wait_for(lambda: link.read_machine().points_done >= 5, beat=link)
        sim.faults.estop = True
        assert wait_for(lambda: link.read_machine().state is MachineState.ABORTED)
        status = link.read_machine()
        assert status.reason is JobReason.ESTOP and 5 <= status.points_done < 100
        executed = sim.machine.executed_dwell_s(job_id)
        assert np.all(executed[:status.points_done] == job.dwell_s[:status.points_done])
        assert np.all(executed[status.points_done + 1:] == 0)
        # the part polished so far stays polished: removal = executed dwell x the tool's volume rate
        expected = float(executed.sum()) * GaussianTool(0.6, 5.0, 0.1).volume_per_second_px()
        assert 0 < target.total_nm == pytest.approx(expected, rel=5e-4)
        with pytest.raises(JobRefused, match="spent"):  # the host never re-sends it
            link.load_job(_receipt_for(tmp_path, job), job_id)
        sim.faults.estop = False
        assert link.start_job(job_id).state is MachineState.ABORTED  # a retried start: reported, never re-run
        assert [w[:2] for w in job_writes(sim)] == [(1, job_id), (2, job_id)]  # nothing more reached the wire


def _receipt_for(folder: Path, job: JobFile):  # noqa: ANN202
    other = folder / "copy"
    other.mkdir(exist_ok=True)
    return write_job_file(other, job)


def test_a_used_id_sent_by_another_host_is_refused_by_the_machine(tmp_path: Path) -> None:
    with station(tmp_path, watchdog_timeout_s=1.0) as (sim, link, _):
        job = make_job(1)
        receipt = write_job_file(tmp_path, job)
        link.load_job(receipt, 1)
        link.start_job(1)
        assert wait_for(lambda: link.read_machine().state is MachineState.DONE, beat=link)
        link.close()  # that host goes away; its watchdog trips and the PLC is nobody's until re-armed
        assert wait_for(lambda: sim.watchdog_state.name == "TRIPPED")
        second = PolishingLink("127.0.0.1", sim.port, register_map(), TIMING, job_limits=LIMITS)
        with second:  # a fresh host that knows nothing of job 1, bypassing its own ledger's view of the machine
            second.rearm(timeout_s=1.0)
            second.self_check(timeout_s=1.0)
            second.heartbeat(timeout_s=1.0)
            second._jobs = type(second._jobs)()  # noqa: SLF001 (simulate a host that forgot)
            with pytest.raises(JobRejected) as caught:
                second.load_job(receipt, 1)
        assert caught.value.status.reason is JobReason.JOB_ID_USED


def test_watchdog_trip_mid_run_aborts_the_job(tmp_path: Path) -> None:
    with station(tmp_path, time_scale=20.0, watchdog_timeout_s=0.5) as (sim, link, target):
        job_id = link.next_job_id()
        link.load_job(write_job_file(tmp_path, make_job(job_id, n=100)), job_id)
        link.start_job(job_id)
        assert wait_for(lambda: link.read_machine().points_done >= 3, beat=link)
        # the host stops beating: the machine's interlock sees the trip on its own
        assert sim.machine is not None
        assert wait_for(lambda: sim.machine.snapshot().state.name == "ABORTED")
        snapshot = sim.machine.snapshot()
        assert snapshot.reason.name == "WATCHDOG" and 3 <= snapshot.points_done < 100
        assert target.total_nm > 0


@pytest.mark.parametrize(("damage", "reason"), [
    ("flip", JobReason.FILE_CORRUPT), ("truncate", JobReason.FILE_TRUNCATED), ("crc", JobReason.CRC_MISMATCH),
    ("missing", JobReason.FILE_MISSING),
])
def test_a_damaged_file_is_refused_with_its_reason(tmp_path: Path, damage: str, reason: JobReason) -> None:
    with station(tmp_path) as (sim, link, target):
        job_id = link.next_job_id()
        receipt = write_job_file(tmp_path, make_job(job_id))
        data = receipt.path.read_bytes()
        if damage == "flip":
            receipt.path.write_bytes(data[:200] + bytes([data[200] ^ 0x01]) + data[201:])
        elif damage == "truncate":
            receipt.path.write_bytes(data[: len(data) // 2])
        elif damage == "crc":  # an intact file, but not the one announced
            _receipt_for(tmp_path, make_job(job_id, n=41)).path.replace(receipt.path)
        else:
            receipt.path.unlink()
        with pytest.raises(JobRejected) as caught:
            link.load_job(receipt, job_id)
        assert caught.value.status.state is MachineState.FAULT and caught.value.status.reason is reason
        assert target.chunks == 0
        with pytest.raises(JobRefused):
            link.start_job(job_id)


def test_limits_and_the_gate_refuse_before_the_wire(tmp_path: Path) -> None:
    with station(tmp_path) as (sim, link, _):
        job_id = link.next_job_id()
        too_long = write_job_file(tmp_path, make_job(job_id, dwell_s=25.0))  # above 20 s per point
        with pytest.raises(JobRefused, match="max_dwell_per_point_s"):
            link.load_job(too_long, job_id)
        outside = write_job_file(tmp_path, make_job(job_id + 1, x_max_mm=6.0))
        with pytest.raises(JobRefused, match="travel"):
            link.load_job(outside, job_id + 1)
        fine = write_job_file(tmp_path, make_job(job_id + 2))
        sim.faults.estop = True
        with pytest.raises(JobNotReady, match="emergency stop"):
            link.load_job(fine, job_id + 2)
        sim.faults.estop = False
        sim.faults.freeze_heartbeat_echo = True
        link.heartbeat(timeout_s=1.0)
        with pytest.raises(HeartbeatEchoStale):
            for _ in range(4):  # the echo may trail by two beats before the link calls it stale
                link.heartbeat(timeout_s=1.0)
        with pytest.raises(JobNotReady):
            link.load_job(fine, job_id + 2)
        assert job_writes(sim) == []  # nothing reached the wire


def test_a_plc_restart_mid_run_ends_aborted_and_ids_move_on(tmp_path: Path) -> None:
    with station(tmp_path, time_scale=20.0) as (sim, link, _):
        job_id = link.next_job_id()
        link.load_job(write_job_file(tmp_path, make_job(job_id, n=100)), job_id)
        link.start_job(job_id)
        assert wait_for(lambda: link.read_machine().points_done >= 2, beat=link)
        sim.restart(power_cycle=True)
        assert wait_for(lambda: sim.wait_listening(0.1))
        with pytest.raises(DeviceDisconnected):  # the restart dropped the connection: reported at once ...
            link.read_machine(timeout_s=3.0)
        status = link.read_machine(timeout_s=3.0)  # ... and the next call reconnects
        assert status.state is MachineState.ABORTED and status.reason is JobReason.PLC_RESTART
        assert link.next_job_id() > job_id
        fresh = PolishingLink("127.0.0.1", sim.port, register_map(), TIMING, job_limits=LIMITS)
        with fresh:  # a host that restarted too learns the machine's last id
            fresh.connect(timeout_s=2.0)
            fresh.read_machine()
            assert fresh.next_job_id() == job_id + 1


def test_a_refused_load_of_an_id_this_host_never_announced_spends_nothing(tmp_path: Path) -> None:
    # issue 29, finding 1: one "LOAD 65535" (no file) used to make the host refuse every id, after a
    # reconnect too. The machine refuses it (FAULT, job 65535): that id was never loaded or run.
    with station(tmp_path) as (sim, link, _):
        assert sim.machine is not None
        sim.machine.load(65535, 0, 1, 1.0)
        assert sim.machine.wait_idle(WAIT_S)
        status = link.read_machine()
        assert (status.state, status.job_id, status.reason) == (MachineState.FAULT, 65535, JobReason.FILE_MISSING)
        job_id = link.next_job_id()
        assert job_id == 1
        link.load_job(write_job_file(tmp_path, make_job(job_id)), job_id)
        link.start_job(job_id)
        assert wait_for(lambda: link.read_machine().state is MachineState.DONE, beat=link)
        link.close()  # a reconnect reads the machine again
        link.read_machine()
        assert link.next_job_id() == 2
