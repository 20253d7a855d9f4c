"""The loop under faults, end to end on the small simulated polishing station: each ends in a clear, recorded state.

Faults come through the simulators' own switches (e-stop, a PLC restart, a changed aperture) or,
for a job file damaged on its way to the machine, through a link double at the loop's ``link``
seam that spoils the file (or the announced CRC) and then calls the real link. In every case: the
loop ends in a terminal phase with its reason, the record has the run and the transitions, and no
job id is loaded twice.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from polishing_stations import CountingLink, polishing_config, polishing_session, run_campaign, when_machine_has_points
from wavestack.polish.recorder import read_polish_campaign

pytestmark = pytest.mark.slow

# slow enough that a fault lands mid-run: ~4000 simulated s of dwell take ~8 s at 500x
SLOW_MACHINE = {"time_scale = 2000.0": "time_scale = 500.0"}


def _no_job_twice(session, link: CountingLink) -> None:
    assert all(count == 1 for count in link.loads.values()), link.loads
    assert all(count <= 1 for count in link.starts.values()), link.starts
    files = sorted(p.name for p in session.job_folder.iterdir() if p.suffix == ".wsjob")
    assert len(files) == len(set(files)) == len(link.loads)


def _recorded(path: Path) -> dict:
    campaign = read_polish_campaign(path)
    assert campaign.damage == ()
    return {"events": [f"{phase}: {reason}" for phase, reason in campaign.events], "runs": len(campaign.runs),
            "states": [r.machine_state for r in campaign.runs], "measured": [r.measured_rms_nm for r in campaign.runs],
            "job_ids": [r.job_id for r in campaign.runs]}


@pytest.mark.parametrize("fault", ["estop", "watchdog", "power-cycle"])
def test_a_run_stopped_partway_keeps_its_removal_and_is_never_resent(tmp_path: Path, fault: str) -> None:
    config = polishing_config(tmp_path, small=True, replacements=SLOW_MACHINE)
    record = tmp_path / "campaign.h5"
    with polishing_session(config) as session:
        simulator = session.devices.plc_simulator
        actions = {
            "estop": lambda: setattr(simulator.faults, "estop", True),
            # the host cannot reach the PLC for longer than its watchdog (4 s): the watchdog trips
            "watchdog": lambda: simulator.restart(downtime_s=5.0),
            "power-cycle": lambda: simulator.restart(downtime_s=0.2, power_cycle=True),
        }
        injectors = []

        def on_event(phase: str, reason: str) -> None:
            if phase == "polishing":
                injectors.append(when_machine_has_points(session, actions[fault], points=20))

        link = CountingLink(session.link)
        summary, events = run_campaign(session, max_runs=3, link=link, record=record, on_event=on_event)
        for thread in injectors:
            thread.join()
        machine = simulator.machine.snapshot()
        _no_job_twice(session, link)
    assert summary.state.phase.value == "faulted", summary.state
    (row,) = summary.runs  # one job, never sent again
    reason = {"estop": "ESTOP", "watchdog": "WATCHDOG", "power-cycle": "PLC_RESTART"}[fault]
    assert (machine.state.name, machine.reason.name) == ("ABORTED", reason)  # the simulator's own account
    assert row.machine_reason == reason, row
    if fault == "watchdog":  # a tripped PLC answers no read until an operator re-arms it: progress as last read
        assert row.machine_state == "UNKNOWN" and 0 <= row.points_done <= machine.points_done
    else:
        assert row.machine_state == "ABORTED" and row.points_done == machine.points_done
    assert 20 <= machine.points_done < row.points
    # the part polished so far stays polished: measured once more, better than before
    assert math.isfinite(row.measured_rms_nm) and row.measured_rms_nm < row.rms_before_nm
    recorded = _recorded(record)
    assert recorded["runs"] == 1 and recorded["states"] == [row.machine_state] and recorded["job_ids"] == [row.job_id]
    assert recorded["events"][-1].startswith("faulted:") and reason in recorded["events"][-1]


def _corrupt(receipt):
    data = bytearray(Path(receipt.path).read_bytes())
    data[len(data) // 2] ^= 0x5A  # one byte flipped in the body
    Path(receipt.path).write_bytes(bytes(data))


def _truncate(receipt):
    data = Path(receipt.path).read_bytes()
    Path(receipt.path).write_bytes(data[: len(data) // 2])


def _crc(receipt):
    return dataclasses.replace(receipt, crc32=receipt.crc32 ^ 0x1)  # the file intact, the announcement not


@pytest.mark.parametrize(("damage", "reason"), [(_corrupt, "FILE_CORRUPT"), (_truncate, "FILE_TRUNCATED"),
                                                (_crc, "CRC_MISMATCH")], ids=["corrupt", "truncated", "crc"])
def test_a_damaged_job_is_refused_recorded_and_not_resent(tmp_path: Path, damage, reason: str) -> None:
    config = polishing_config(tmp_path, small=True)
    record = tmp_path / "campaign.h5"
    with polishing_session(config) as session:
        surface = session.devices.bench.optic.surface
        before = surface.revision
        link = CountingLink(session.link, damage)
        summary, events = run_campaign(session, max_runs=3, link=link, record=record)
        _no_job_twice(session, link)
        assert surface.revision == before  # nothing polished
    assert summary.state.phase.value == "faulted" and reason in (summary.state.reason or "")
    (row,) = summary.runs
    assert row.machine_state == "FAULT" and row.machine_reason == reason and row.points_done <= 0
    assert [phase for phase, _ in events][-2:] == ["handing-off", "faulted"]
    recorded = _recorded(record)
    assert recorded["runs"] == 1 and recorded["states"] == ["FAULT"]


def test_a_changed_aperture_stops_the_loop_before_any_job(tmp_path: Path) -> None:
    config = polishing_config(tmp_path, small=True)
    record = tmp_path / "campaign.h5"
    with polishing_session(config) as session:
        optic = session.devices.bench.optic
        smaller = dataclasses.replace(optic.aperture, radius_px=optic.aperture.radius_px - 12.0)

        def on_event(phase: str, reason: str) -> None:
            if phase == "polishing":  # the optic is moved while the machine polishes
                optic.set_aperture(smaller)

        link = CountingLink(session.link)
        summary, events = run_campaign(session, max_runs=3, link=link, record=record, on_event=on_event)
        _no_job_twice(session, link)
    assert summary.state.phase.value == "faulted" and "aperture changed" in (summary.state.reason or "")
    (row,) = summary.runs  # the first job ran; no second job on the changed aperture
    assert row.machine_state == "DONE" and math.isnan(row.measured_rms_nm)
    assert len(link.loads) == 1
    assert "aperture changed" in _recorded(record)["events"][-1]


def test_a_plc_service_restart_mid_run_is_ridden_through(tmp_path: Path) -> None:
    """A restart of the PLC's Modbus service (not a power cycle) shorter than the watchdog: the job goes on."""
    config = polishing_config(tmp_path, small=True)
    with polishing_session(config) as session:
        simulator = session.devices.plc_simulator
        injectors = []

        def on_event(phase: str, reason: str) -> None:
            if phase == "polishing":
                injectors.append(when_machine_has_points(session, lambda: simulator.restart(downtime_s=0.3),
                                                         points=20))

        link = CountingLink(session.link)
        summary, _ = run_campaign(session, max_runs=1, link=link, on_event=on_event)
        for thread in injectors:
            thread.join()
        _no_job_twice(session, link)
    assert summary.state.phase.value in ("max-runs", "target-met"), summary.state
    (row,) = summary.runs
    assert row.machine_state == "DONE" and row.points_done == row.points
    assert row.measured_rms_nm < row.rms_before_nm / 2


def test_the_operator_stop_ends_interrupted(tmp_path: Path) -> None:
    config = polishing_config(tmp_path, small=True, replacements=SLOW_MACHINE)
    with polishing_session(config) as session:
        import threading

        stop = threading.Event()
        injectors = []

        def on_event(phase: str, reason: str) -> None:
            if phase == "polishing":
                injectors.append(when_machine_has_points(session, stop.set, points=5))

        link = CountingLink(session.link)
        summary, _ = run_campaign(session, max_runs=3, link=link, on_event=on_event, stop=stop)
        for thread in injectors:
            thread.join()
        _no_job_twice(session, link)
    assert summary.state.phase.value == "interrupted"
    assert len(summary.runs) == 1 and summary.runs[0].machine_state == "UNKNOWN"
    assert np.isnan(summary.runs[0].measured_rms_nm)
