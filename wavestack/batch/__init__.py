"""Campaigns: re-analysis of many recordings on Dask (``wavestack batch``).

Modules by job: :mod:`~wavestack.batch.plan` (recordings into tasks, the resume hashes),
:mod:`~wavestack.batch.task` (what a worker runs: paths in, plain rows out),
:mod:`~wavestack.batch.rows` (those rows), :mod:`~wavestack.batch.table` (the Parquet results,
written by the client only), :mod:`~wavestack.batch.progress` (sets done, rate, time left),
:mod:`~wavestack.batch.cluster` (a local cluster or a remote scheduler) and
:mod:`~wavestack.batch.campaign` (running it all). See docs/batch.md.
"""

from __future__ import annotations

from wavestack.batch.campaign import CampaignPlan, CampaignReport, assemble, prepare_campaign, run_campaign
from wavestack.batch.cluster import campaign_client, local_workers
from wavestack.batch.plan import MIN_BLOCK_SETS, RecordingPlan, Task, file_sha256, plan_recording, settings_hash
from wavestack.batch.progress import Progress, progress_bar
from wavestack.batch.rows import ResultRow, SkippedItem, TaskOutcome
from wavestack.batch.table import RecordingSummary, ResultsStore
from wavestack.batch.task import analyse, fit_block

__all__ = ["CampaignPlan", "CampaignReport", "assemble", "prepare_campaign", "MIN_BLOCK_SETS", "Progress", "RecordingPlan", "RecordingSummary", "ResultRow",
           "ResultsStore", "SkippedItem", "Task", "TaskOutcome", "analyse", "campaign_client", "file_sha256",
           "fit_block", "local_workers", "plan_recording", "progress_bar", "run_campaign",
           "settings_hash"]
