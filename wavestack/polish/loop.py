"""The closed loop: measure -> check -> solve -> program -> hand off -> wait -> measure, until it stops.

:class:`PolishingLoop` drives :mod:`~wavestack.polish.state`'s machine with the loop kernel's runner
(:func:`~wavestack.loop.run_machine`): each phase does its one piece of work and turns what
happened into an event; :func:`~wavestack.polish.state.advance` decides where to go. The pieces:
the measurement (the station service's :class:`~wavestack.station.LiveMaps`, averaged by
:func:`~wavestack.polish.measurement.average_surface`), the plan
(:func:`~wavestack.polish.planning.plan_job`), the job-level rules
(:func:`~wavestack.polish.job_checks.check_job`), the hand-off and the wait
(:mod:`~wavestack.polish.handoff`). Every transition is recorded with its reason; a run's row is
written when its job starts and completed when the next measurement (or the end) comes; each
completed run goes to ``on_run`` (its row) and ``on_run_maps`` (its row and maps, for figures).

After a job the machine ended early (an e-stop, a watchdog trip, a fault) the loop still takes one
more measurement if the station can give one: it is recorded as that run's result (what the part
looks like after the partial job), and the loop ends faulted without sending anything more.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wavestack.config.polishing import PolishingConfig
from wavestack.drivers.errors import DeviceError
from wavestack.drivers.plc import PolishingLink, read_job_key
from wavestack.loop import Transitions, run_machine
from wavestack.pipeline import InputError
from wavestack.pipeline.polishing import ToolInfluence
from wavestack.polish.handoff import MachineEnd, announce_and_start, state_name, wait_for_done, write_job
from wavestack.polish.job_checks import JobRules, JobUnsafe, check_job
from wavestack.polish.measurement import ApertureKey, Measurement, average_surface
from wavestack.polish.planning import NoFittingJob, PlannedJob, job_file_of, plan_job
from wavestack.polish.recorder import CampaignRecorder
from wavestack.polish.run_record import RunMaps, RunRecord, run_finished, run_started
from wavestack.polish.state import LoopEvent, LoopPhase, LoopState, advance, judge_job, judge_measurement
from wavestack.station import LiveMaps, UntrustedMeasurement
from wavestack.pipeline import FormTolerance, SurfaceAnalyzer, SurfaceRequest
from wavestack.pipeline.surface import SpecVerdict

logger = logging.getLogger(__name__)

__all__ = ["CampaignSummary", "LoopOptions", "PolishingLoop"]


@dataclass(frozen=True)
class LoopOptions:
    """What a campaign runs to (the command line's overrides of ``[polishing]`` applied)."""

    target_rms_nm: float
    max_runs: int
    solver: str
    spec: FormTolerance | None = None  # the drawing: the loop stops when it is met, not on the RMS


@dataclass(frozen=True)
class CampaignSummary:
    """How a campaign ended.

    Attributes
    ----------
    state : LoopState
        The terminal state (phase and reason).
    runs : tuple of RunRecord
    rms_nm : tuple of float
        Every trusted measurement's RMS, in order.
    """

    state: LoopState
    runs: tuple[RunRecord, ...] = ()
    rms_nm: tuple[float, ...] = ()
    verdict: SpecVerdict | None = None

    def to_json(self) -> dict[str, object]:
        summary: dict[str, object] = {
            "type": "summary", "final_phase": self.state.phase.value, "reason": self.state.reason,
            "runs_done": self.state.runs_done, "rms_nm": list(self.rms_nm), "job_ids": [row.job_id for row in self.runs]}
        if self.verdict is not None:
            summary["spec"] = self.verdict.as_dict()
        return summary


@dataclass
class _Run:
    """The run in flight: its row, where it is recorded, and what the figures need."""

    row: RunRecord
    index: int | None
    job: PlannedJob
    before: Measurement
    started_s: float
    end: MachineEnd | None = None


@dataclass
class _Campaign:
    state: LoopState = field(default_factory=LoopState)
    measurement: Measurement | None = None
    reference: ApertureKey | None = None
    previous_rms_nm: float | None = None
    planned: PlannedJob | None = None
    run: _Run | None = None
    not_before_ns: int = 0
    runs: list[RunRecord] = field(default_factory=list)
    rms_nm: list[float] = field(default_factory=list)
    verdict: SpecVerdict | None = None  # the last trusted measurement against the drawing


class PolishingLoop:
    """One polishing campaign on a running station (module notes).

    Parameters
    ----------
    config : PolishingConfig
    options : LoopOptions
    link : PolishingLink
        The station's PLC link (thread-safe; the station's thread heartbeats on it).
    maps : LiveMaps
        The station's sink.
    tif : ToolInfluence
        The host's model of the tool.
    job_folder : Path
    stop : threading.Event
        The operator's stop.
    recorder : CampaignRecorder, optional
    target_nm : ndarray (H, W), optional
        The target figure subtracted from every measurement.
    on_run : callable, optional
        Gets every completed :class:`RunRecord`.
    on_run_maps : callable, optional
        ``on_run_maps(row, maps)`` with the run's :class:`RunMaps` (the per-run figures).
    on_event : callable, optional
        ``on_event(phase, reason)`` for every transition.
    """

    def __init__(self, config: PolishingConfig, options: LoopOptions, *, link: PolishingLink, maps: LiveMaps,
                 tif: ToolInfluence, job_folder: Path, stop: threading.Event, recorder: CampaignRecorder | None = None,
                 target_nm: NDArray[np.floating] | None = None, on_run: Callable[[RunRecord], None] | None = None,
                 on_run_maps: Callable[[RunRecord, RunMaps], None] | None = None,
                 on_event: Callable[[str, str], None] | None = None) -> None:
        self._config, self._settings, self._options = config, config.polishing, options
        self._link, self._maps, self._tif = link, maps, tif
        self._folder, self._stop, self._recorder = Path(job_folder), stop, recorder
        self._target = target_nm
        self._on_run, self._on_run_maps = on_run, on_run_maps
        self._note = Transitions("polish", recorder=recorder, on_event=on_event)
        station = config.station
        assert station.plc is not None  # parse_polishing_config requires [plc]
        self._io_timeout_s = station.plc.link.io_timeout_s * 4
        self._poll_s = min(0.25, station.plc.link.watchdog_timeout_s / 4)
        self._measure_timeout_s = self._settings.max_results_per_measurement * station.station.frame_timeout_s
        self._rules = JobRules(self._settings.max_removal_nm_per_run, self._settings.max_total_dwell_s,
                               self._settings.freshness_s)
        key_file = station.plc.job_key_path()
        try:
            self._job_key = None if key_file is None else read_job_key(key_file)
        except ValueError as error:
            raise InputError(f"{config.source}: [plc] job_key_file: {error}") from None

    # ------------------------------------------------------------------ the loop
    def run(self) -> CampaignSummary:
        """Run the campaign to a terminal phase; returns how it ended (never raises a device error)."""
        c = _Campaign()
        steps = {LoopPhase.MEASURING: self._measure, LoopPhase.CHECKING: self._check, LoopPhase.SOLVING: self._solve,
                 LoopPhase.PROGRAMMING: self._program, LoopPhase.HANDING_OFF: self._hand_off,
                 LoopPhase.POLISHING: self._wait}
        run_machine(c, steps, advance=advance, stop=self._stop, stop_event=LoopEvent.STOP, note=self._note)
        if c.run is not None:  # a run the loop did not see measured after
            self._finish_run(c, None)
        return CampaignSummary(c.state, tuple(c.runs), tuple(c.rms_nm), c.verdict)

    # ------------------------------------------------------------------ phases
    def _take_measurement(self, c: _Campaign) -> Measurement:
        s = self._settings
        samples = self._maps.collect(s.averaged_results, max_results=s.max_results_per_measurement,
                                     not_before_ns=c.not_before_ns, timeout_s=self._measure_timeout_s, stop=self._stop)
        return average_surface(samples, wavelength_nm=self._config.station.station.wavelength_nm,
                               reflection_factor=s.reflection_factor, min_count=s.averaged_results,
                               reference=c.reference, target_nm=self._target, not_before_ns=c.not_before_ns,
                               max_noise_rms_nm=s.max_noise_rms_nm, edge_px=s.edge_px)

    def _measure(self, c: _Campaign) -> tuple[LoopEvent, str]:
        try:
            measurement = self._take_measurement(c)
        except UntrustedMeasurement as error:
            if self._stop.is_set():
                return LoopEvent.STOP, "stopped by the operator while measuring"
            return LoopEvent.UNTRUSTED, f"measurement not trusted: {error}"
        self._accept(c, measurement)
        if c.run is not None:
            self._finish_run(c, measurement)
        return LoopEvent.MEASURED, (f"{measurement.count} maps averaged: RMS {measurement.rms_nm:.2f} nm, "
                                    f"PV {measurement.pv_nm:.1f} nm, noise {measurement.noise_rms_nm:.3f} nm")

    def _accept(self, c: _Campaign, measurement: Measurement) -> None:
        c.measurement = measurement
        c.reference = c.reference or measurement.aperture
        c.rms_nm.append(measurement.rms_nm)
        if self._recorder is not None:
            self._recorder.measurement(measurement)

    def _check(self, c: _Campaign) -> tuple[LoopEvent, str]:
        measurement = c.measurement
        assert measurement is not None
        if self._options.spec is not None:  # the surface error against the drawing (target figure subtracted)
            valid = measurement.mask & np.isfinite(measurement.surface_nm)
            try:
                analyzer = SurfaceAnalyzer(valid, SurfaceRequest(tolerance=self._options.spec))
                c.verdict = analyzer.measure(measurement.surface_nm).verdict
            except ValueError as error:  # never polish against a drawing that could not be checked
                return LoopEvent.FAULT, f"the drawing cannot be checked on this measurement: {error}"
        return judge_measurement(measurement.rms_nm, c.previous_rms_nm, c.state.runs_done,
                                 target_rms_nm=self._options.target_rms_nm, max_runs=self._options.max_runs,
                                 min_improvement=self._settings.min_improvement, verdict=c.verdict)

    def _solve(self, c: _Campaign) -> tuple[LoopEvent, str]:
        assert c.measurement is not None
        m = c.measurement
        try:
            c.planned = plan_job(m, self._tif, self._settings, solver=self._options.solver)
        except NoFittingJob as error:
            if c.state.runs_done == 0:  # not one run possible: the limits or the solver need an operator
                return LoopEvent.FAULT, f"no job: {error}"
            return LoopEvent.NO_GAIN, f"at the floor within the machine's limits: {error}"
        except ValueError as error:  # a solver's refusal
            return LoopEvent.FAULT, f"no job: {error}"
        p = c.planned
        what = (f"{self._options.solver} dwell ({p.gentleness:g}): {p.program.x_mm.size} points, "
                f"{p.program.total_dwell_s:.0f} s; predicted {p.predicted_rms_nm:.2f} nm RMS ({p.solve_s:.1f} s)"
                + (f"; {p.floor.describe()}" if p.floor is not None else ""))
        verdict = judge_job(m.rms_nm, p.predicted_rms_nm, None if p.floor is None else p.floor.floor_nm,
                            floor_tolerance=self._settings.floor_tolerance,
                            min_improvement=self._settings.min_improvement)
        if verdict is LoopEvent.AT_FLOOR:
            return verdict, (f"floor reached: RMS {m.rms_nm:.2f} nm is within "
                             f"{self._settings.floor_tolerance:.0%} of the best job's {what}")
        if verdict is LoopEvent.NO_GAIN:
            return verdict, (f"at the floor: the best job within the limits is not predicted to improve "
                             f"on {m.rms_nm:.2f} nm ({what})")
        return verdict, what

    def _program(self, c: _Campaign) -> tuple[LoopEvent, str]:
        assert c.measurement is not None and c.planned is not None and c.reference is not None
        try:
            check_job(self._rules, dwell_s=c.planned.dwell_s, removal_nm=c.planned.removal_nm,
                      job_aperture=c.measurement.aperture, measurement=c.measurement, campaign_aperture=c.reference,
                      now_ns=time.time_ns())
        except JobUnsafe as error:
            return LoopEvent.FAULT, f"job refused on the host: {error}"
        return LoopEvent.PROGRAMMED, "program within the machine's and the job's limits"

    def _hand_off(self, c: _Campaign) -> tuple[LoopEvent, str]:
        """Write the job, record it, announce and start it: a job refused is on record with the machine's reason."""
        assert c.measurement is not None and c.planned is not None
        m, planned = c.measurement, c.planned
        try:
            job_id = self._link.next_job_id()
            receipt = write_job(self._folder, job_file_of(planned, job_id, self._tif, m.aperture.to_json(),
                                                          self._settings.pixel_mm), self._job_key)
        except (DeviceError, OSError, ValueError) as error:
            return LoopEvent.FAULT, f"job not written: {error}"
        row = run_started(c.state.runs_done + 1, job_id, rms_before_nm=m.rms_nm, pv_before_nm=m.pv_nm,
                          noise_before_nm=m.noise_rms_nm, predicted_rms_nm=planned.predicted_rms_nm,
                          predicted_pv_nm=planned.predicted_pv_nm, total_dwell_s=float(receipt.total_dwell_s),
                          points=int(receipt.point_count), job_crc32=int(receipt.crc32), started_unix_s=time.time(),
                          solve_s=planned.solve_s,
                          floor_nm=planned.floor.floor_nm if planned.floor is not None else float("nan"))
        index = None
        if self._recorder is not None:
            index = self._recorder.run_started(row, measured_nm=m.surface_nm, dwell_s=planned.dwell_s,
                                               predicted_residual_nm=planned.residual_nm,
                                               job_file=Path(receipt.path).read_bytes())
        c.run = _Run(row, index, planned, m, time.monotonic())
        c.previous_rms_nm = m.rms_nm
        try:
            announce_and_start(self._link, receipt, job_id, timeout_s=self._io_timeout_s)
        except (DeviceError, ValueError) as error:  # JobRefused, JobRejected, a PLC that did not answer
            status = getattr(error, "status", None)
            c.run.end = MachineEnd(state_name(getattr(status, "state", "")) or "NOT_STARTED",
                                   state_name(getattr(status, "reason", "")), int(getattr(status, "points_done", 0)),
                                   int(getattr(status, "point_count", receipt.point_count)), str(error), time.time_ns())
            code = f" ({c.run.end.state} {c.run.end.reason})" if c.run.end.reason else ""
            return LoopEvent.FAULT, f"job {job_id} not started{code}: {error}"
        return LoopEvent.HANDED_OFF, (f"job {job_id} started: {receipt.point_count} points, "
                                      f"{receipt.total_dwell_s:.0f} s dwell, CRC-32 {receipt.crc32:08x}")

    def _wait(self, c: _Campaign) -> tuple[LoopEvent, str]:
        assert c.run is not None
        end = wait_for_done(self._link, c.run.row.job_id, timeout_s=self._settings.done_timeout_s,
                            poll_s=self._poll_s, io_timeout_s=self._io_timeout_s, stop=self._stop,
                            heartbeat=lambda: self._maps.last_heartbeat)
        c.run.end = end
        c.not_before_ns = end.done_ns
        if end.done:
            return LoopEvent.MACHINE_DONE, end.detail
        if end.reason == "STOPPED":
            return LoopEvent.STOP, end.detail
        self._measure_after_fault(c)
        return LoopEvent.FAULT, f"machine {end.state} ({end.reason or 'no reason'}): {end.detail}"

    def _measure_after_fault(self, c: _Campaign) -> None:
        """One more measurement for the record of a job that ended early (never used for a job)."""
        try:
            measurement = self._take_measurement(c)
        except UntrustedMeasurement as error:
            logger.warning("no measurement after the machine's fault: %s", error)
            return
        self._accept(c, measurement)
        self._finish_run(c, measurement)

    # ------------------------------------------------------------------ records
    def _finish_run(self, c: _Campaign, after: Measurement | None) -> None:
        run = c.run
        assert run is not None
        c.run = None
        end = run.end
        row = run_finished(run.row, measured_rms_nm=after.rms_nm if after else float("nan"),
                           measured_pv_nm=after.pv_nm if after else float("nan"),
                           machine_state=end.state if end else "UNKNOWN", machine_reason=end.reason if end else "",
                           points_done=end.points_done if end else -1, run_s=time.monotonic() - run.started_s)
        c.runs.append(row)
        if self._recorder is not None and run.index is not None:
            self._recorder.run_updated(run.index, row, after.surface_nm if after else None)
        if self._on_run is not None:
            self._on_run(row)
        if self._on_run_maps is not None:
            self._on_run_maps(row, RunMaps(run.before.surface_nm, run.job.dwell_s, run.job.residual_nm,
                                           after.surface_nm if after else None))
