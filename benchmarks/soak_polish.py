"""The soak's polishing campaign: the closed loop with job hand-offs under the station soak's fault schedule.

Run:  .venv/bin/python benchmarks/soak.py --polish --duration-s 1800 --seed 1 --fault-every-s 10

Opens what ``wavestack polish`` opens (the embedded polishing station unless ``--config``: the
simulated camera, piezo and PLC with its polishing machine, which polishes the optic's surface)
and runs campaigns of the polishing loop back to back (``--polish-runs`` runs each, 2 by default).
Each campaign starts on a fresh part: the optic's surface is set back to its first heights through
the simulator's own surface (an anti-removal of what the machine took away). The station soak's
fault schedule (:mod:`soak_faults`) hits the camera, the piezo and the PLC meanwhile, through the
simulators' switches; a fault ends a campaign (the loop stops on any fault) and the next begins.
The monitor samples RSS and plays the operator as in the station soak.

What it checks, besides the station soak's targets (RSS flat within +-5 %, every fault accounted,
no unhandled exception):

- **nothing applied twice**: no job id handed off twice, and the machine executed at no point of
  a job more dwell than its file asked (checked as each run ends, from the machine's own record);
- **nothing lost**: every job a run handed off is in the job folder with the machine's end on its
  run (DONE, ABORTED with its reason, a refused load with its reason), the points the machine
  dwelt on are the points it reported done, and every job the machine loaded is a run of the host's.
"""

from __future__ import annotations

import threading
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from soak_observe import Observer

from wavestack.config.polishing import PolishingConfig
from wavestack.polish import RunRecord
from wavestack.polish.loop import LoopOptions, PolishingLoop
from wavestack.polish.session import open_session

__all__ = ["CampaignEnd", "PolishRunner", "polish_checks"]


@dataclass(frozen=True)
class CampaignEnd:
    """How one campaign ended: its terminal phase and reason, and the job ids of its runs."""

    t_s: float
    phase: str
    reason: str
    job_ids: tuple[int, ...]


@dataclass
class PolishRunner:
    """Runs campaigns back to back on one polishing session (the interface the soak's monitor uses)."""

    config: PolishingConfig
    observer: Observer
    runs_per_campaign: int = 2
    stop: threading.Event = field(default_factory=threading.Event)
    runs: list[RunRecord] = field(default_factory=list)
    campaigns: list[CampaignEnd] = field(default_factory=list)
    crashes: int = 0
    restarts: int = 0
    incarnation: int = 0
    started_t_s: float = 0.0
    error: str = ""
    _devices: Any = None
    _job_folder: Path | None = None
    _campaign_stop: threading.Event = field(default_factory=threading.Event)
    final: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    summaries: list[Any] = field(default_factory=list)  # the station soak's report reads it (no station summary)

    @property
    def devices(self) -> Any:
        return self._devices

    def totals(self) -> tuple[Any, int]:
        devices = self._devices
        trips = devices.plc_simulator.watchdog_trips if devices is not None and devices.plc_simulator else 0
        return self.observer.last_counters, trips

    def request_restart(self) -> None:
        """A stuck station is only reported here: the campaign goes on (the soak passes ``continue``)."""

    def stop_all(self) -> None:
        self.stop.set()
        self._campaign_stop.set()

    def _run_ended(self, record: RunRecord) -> None:
        """A run ended: keep it and check its job against the machine's record now (module notes)."""
        self.runs.append(record)
        devices, folder = self._devices, self._job_folder
        machine = devices.plc_simulator.machine if devices is not None and devices.plc_simulator else None
        if machine is not None and folder is not None and record.job_id > 0:
            self.problems.extend(_check_run(record, machine, folder))

    def run(self) -> None:
        """Thread target: one session, campaigns until :meth:`stop_all`; the checks read it after."""
        try:
            with ExitStack() as stack:
                session = open_session(self.config, stack, sinks=(self.observer.add,))
                self._devices, self._job_folder = session.devices, session.job_folder
                self.incarnation, self.started_t_s = 1, self.observer.now()
                surface = session.devices.bench.optic.surface
                first = surface.heights_nm().copy()
                options = LoopOptions(target_rms_nm=0.5, max_runs=self.runs_per_campaign,
                                      solver=self.config.polishing.solver)
                while not self.stop.is_set():
                    surface.apply_removal(surface.heights_nm() - first)  # a fresh part: back to the first heights
                    loop = PolishingLoop(self.config, options, link=session.link, maps=session.maps,
                                         tif=session.tif, job_folder=session.job_folder, stop=self._campaign_stop,
                                         target_nm=session.target_nm, on_run=self._run_ended)
                    summary = loop.run()
                    self.campaigns.append(CampaignEnd(self.observer.now(), summary.state.phase.value,
                                                      summary.state.reason or "",
                                                      tuple(r.job_id for r in summary.runs)))
                self.final = polish_checks(self)  # while the machine and its folder are still there
        except Exception as error:  # noqa: BLE001 - what escapes the loop is a soak failure, reported
            self.crashes += 1
            self.error = f"{type(error).__name__}: {error}"
        finally:
            self._devices = None
            self.stop.set()


def _check_run(record: RunRecord, machine: Any, folder: Path) -> list[str]:
    """One ended run's job: in the folder, ended by the machine, never more dwell than asked."""
    path = folder / f"job-{record.job_id:05d}.wsjob"
    if not path.is_file():
        return [f"job {record.job_id}: its file is gone from the job folder"]
    problems = [] if record.machine_state else [f"job {record.job_id}: the run has no machine end"]
    if record.job_id not in machine.used_job_ids:
        if record.machine_state in ("DONE", "ABORTED", "RUNNING"):
            problems.append(f"job {record.job_id}: {record.machine_state} but never loaded by the machine")
        return problems
    machine.wait_idle(30.0)  # a job the loop stopped waiting for (the soak's end) finishes or stops first
    try:
        executed = machine.executed_dwell_s(record.job_id)
    except KeyError:
        return problems  # loaded, never started (a fault between the load and the start)
    asked = _dwell(path)
    if executed.shape != asked.shape or bool(np.any(executed > asked * (1 + 1e-9) + 1e-12)):
        problems.append(f"job {record.job_id}: executed more dwell than the file asked")
    done = int(np.count_nonzero(executed))
    if record.points_done >= 0 and done > record.points_done + 1:  # the point under way at a stop: partial
        problems.append(f"job {record.job_id}: {done} points dwelt on, the run reported {record.points_done}")
    return problems


def polish_checks(runner: PolishRunner) -> dict[str, Any]:
    """The campaign as a whole: ids handed off once, every job the machine loaded a run of the host's."""
    devices = runner.devices
    machine = devices.plc_simulator.machine if devices is not None and devices.plc_simulator else None
    problems = list(runner.problems)
    if machine is None:
        return {"problems": [*problems, "no machine to check"], "jobs": 0}
    handed = [r for r in runner.runs if r.job_id > 0]
    ids = [r.job_id for r in handed]
    if len(set(ids)) != len(ids):
        problems.append(f"a job id handed off twice: {sorted(i for i in set(ids) if ids.count(i) > 1)}")
    unknown = sorted(machine.used_job_ids - set(ids))
    if unknown:
        problems.append(f"jobs the machine loaded with no run of the host's: {unknown}")
    states: dict[str, int] = {}
    for record in handed:
        states[record.machine_state or "none"] = states.get(record.machine_state or "none", 0) + 1
    return {"problems": problems, "jobs": len(handed), "machine_ids": len(machine.used_job_ids),
            "campaigns": len(runner.campaigns), "machine_states": states,
            "campaign_ends": _count(f"{c.phase}" for c in runner.campaigns)}


def _dwell(path: Path) -> np.ndarray:
    """The dwell column of a job file, as the soak reads it (the body's JSON)."""
    import json

    data = path.read_bytes()
    body = data[:data.rindex(b"\nwsjob-crc32 ")]
    return np.array([row[2] for row in json.loads(body)["points"]], dtype=np.float64)


def _count(items: Any) -> dict[str, int]:
    counts: dict[str, int] = {}
    for item in items:
        counts[item] = counts.get(item, 0) + 1
    return counts


