"""Closed-loop polishing: measure the surface, compute the dwell, hand the job to the machine, measure again.

One job per module: the loop's life as data (:mod:`.state`), the measurement (:mod:`.measurement`),
the job-level safety rules (:mod:`.job_checks`), a run as a value (:mod:`.run_record`), the
campaign's HDF5 record (:mod:`.recorder`), the per-run figures (:mod:`.plots`), and the loop that
drives the station, the solver and the machine through them (:mod:`.loop`).
"""

from __future__ import annotations

from wavestack.polish.job_checks import JobRules, JobUnsafe, check_job
from wavestack.polish.measurement import (
    ApertureKey,
    MapSample,
    Measurement,
    UntrustedMeasurement,
    average_surface,
    remove_ptt,
    surface_stats,
)
from wavestack.polish.plots import plot_run, run_plot_name
from wavestack.polish.recorder import CampaignRecorder
from wavestack.polish.run_record import RunRecord, run_finished, run_line, run_started
from wavestack.polish.state import (
    TERMINAL_PHASES,
    TRANSITIONS,
    LoopEvent,
    LoopPhase,
    LoopState,
    advance,
    judge_job,
    judge_measurement,
)

__all__ = [
    "ApertureKey", "CampaignRecorder", "JobRules", "JobUnsafe", "LoopEvent", "LoopPhase", "LoopState", "MapSample",
    "Measurement", "RunRecord", "TERMINAL_PHASES", "TRANSITIONS", "UntrustedMeasurement", "advance",
    "average_surface", "check_job", "judge_job", "judge_measurement", "plot_run", "remove_ptt", "run_finished", "run_line",
    "run_plot_name", "run_started", "surface_stats",
]
