"""Closed-loop polishing: measure the surface, compute the dwell, hand the job to the machine, measure again.

One job per module: the loop's life as data (:mod:`.state`, on the loop kernel's table), the
measurement (:mod:`.measurement`, from the station service's maps), the job-level safety rules
(:mod:`.job_checks`), a run as a value (:mod:`.run_record`) and as the history table the web view
reads (:mod:`.history`), the campaign's record (:mod:`.recorder`, on the kernel's checksummed
record), the session on the station service (:mod:`.session`), and the loop that drives the
station, the solver and the machine through them (:mod:`.loop`, on the kernel's runner).
"""

from __future__ import annotations

from wavestack.polish.job_checks import JobRules, JobUnsafe, check_job
from wavestack.polish.measurement import ApertureKey, Measurement, average_surface, surface_stats
from wavestack.polish.history import campaign_history
from wavestack.polish.recorder import CampaignRecorder, PolishCampaign, read_polish_campaign
from wavestack.polish.run_record import RunMaps, RunRecord, run_finished, run_line, run_started
from wavestack.polish.state import (
    TABLE,
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
    "ApertureKey", "CampaignRecorder", "JobRules", "JobUnsafe", "LoopEvent", "LoopPhase", "LoopState", "Measurement",
    "PolishCampaign", "RunMaps", "RunRecord", "TABLE", "TERMINAL_PHASES", "TRANSITIONS", "advance", "average_surface",
    "campaign_history", "check_job", "judge_job", "judge_measurement", "read_polish_campaign",
    "run_finished", "run_line", "run_started", "surface_stats",
]
