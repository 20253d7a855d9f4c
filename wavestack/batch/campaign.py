"""A campaign: plan the recordings, run their tasks on a Dask client, commit each recording's rows
as soon as all its tasks are back.

The client alone writes the results (:class:`~wavestack.batch.table.ResultsStore`); workers only
read recordings. A task that fails with an exception (a bug, a worker lost) leaves its recording
uncommitted and reported, so ``--resume`` retries it; every other recording goes on.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from wavestack.batch.plan import MIN_BLOCK_SETS, RecordingPlan, plan_recording, whole_recording
from wavestack.batch.progress import Progress
from wavestack.batch.rows import ResultRow, TaskOutcome, renumbered
from wavestack.batch.table import RecordingSummary, ResultsStore
from wavestack.batch.task import analyse
from wavestack.pipeline import InputError

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class CampaignReport:
    """What a campaign did.

    Attributes
    ----------
    analysed : tuple of RecordingSummary
        Recordings committed by this run, in the order they finished.
    resumed : tuple of str
        Recordings skipped because the results already hold them (same file and settings).
    failed : tuple of str
        One line per recording whose task raised (not committed: ``--resume`` retries it).
    """

    analysed: tuple[RecordingSummary, ...] = ()
    resumed: tuple[str, ...] = ()
    failed: tuple[str, ...] = ()


@dataclass
class _Pending:
    """Outcomes of one recording's tasks as they come back."""

    plan: RecordingPlan
    outcomes: dict[int, TaskOutcome] = field(default_factory=dict)
    tasks: int = 0


@dataclass(frozen=True)
class CampaignPlan:
    """What a campaign will run: the recordings to analyse and those the results already hold.

    Attributes
    ----------
    plans : tuple of RecordingPlan
    resumed : tuple of str
        Recordings skipped: already committed with the same file and settings (``--resume``), or
        a second copy of a file given twice.
    config_text : str or None
    """

    plans: tuple[RecordingPlan, ...]
    resumed: tuple[str, ...]
    config_text: str | None


def prepare_campaign(paths: Sequence[str], store: ResultsStore, *, config_text: str | None = None,
                     resume: bool = False, min_block_sets: int = MIN_BLOCK_SETS) -> CampaignPlan:
    """Hash and plan every recording (in this process, before any cluster starts).

    Parameters
    ----------
    paths : sequence of str
        Recordings (station, polish; other files are planned as reported skips).
    config_text : str, optional
        Station configuration (TOML) to process with; None: each recording's own.
    resume : bool
        Skip recordings already in ``store`` with the same file hash and settings. Without it,
        ``store`` must hold no results yet.

    Raises
    ------
    InputError
        A path that cannot be read, or results present without ``resume``.
    """
    if store.has_results() and not resume:
        raise InputError(f"{store.root}: already holds results; pass --resume to continue that campaign, "
                         "or choose another --out")
    done = store.done_keys() if resume else set()
    plans, resumed, seen = [], [], set()
    for path in paths:
        plan = plan_recording(str(path), config_text, min_block_sets=min_block_sets)
        key = (plan.file_sha256, plan.settings_hash)
        if key in done or key in seen:
            resumed.append(plan.path)
            continue
        seen.add(key)
        plans.append(plan)
    return CampaignPlan(tuple(plans), tuple(resumed), config_text)


def run_campaign(campaign: CampaignPlan, store: ResultsStore, client: object, *,
                 on_progress: Callable[[Progress], None] = lambda p: None,
                 on_recording: Callable[[RecordingSummary], None] = lambda s: None) -> CampaignReport:
    """Run ``campaign``'s tasks on ``client`` (a ``distributed.Client``), committing each recording
    to ``store`` as soon as all its tasks are back.

    Example
    -------
    ``wavestack batch`` does, in short::

        campaign = prepare_campaign(paths, store)
        with campaign_client(None, 2) as client:
            report = run_campaign(campaign, store, client)
    """
    if campaign.plans:
        store.write_settings(campaign.plans[0].settings_hash, campaign.config_text)
    return _execute(list(campaign.plans), list(campaign.resumed), store, client, on_progress, on_recording)


def _execute(plans: list[RecordingPlan], resumed: list[str], store: ResultsStore, client: object,
             on_progress: Callable[[Progress], None], on_recording: Callable[[RecordingSummary], None]) -> CampaignReport:
    from distributed import as_completed

    total = sum(p.sets for p in plans)
    pending = {p.key: _Pending(p, tasks=len(p.tasks)) for p in plans}
    tasks = [t for p in plans for t in p.tasks]
    futures = client.map(analyse, tasks, pure=False)  # type: ignore[attr-defined]
    task_of = {f.key: t for f, t in zip(futures, tasks)}
    analysed, failed, done_sets, start = [], [], 0, time.perf_counter()
    on_progress(Progress(0, total, 0, len(plans), 0.0))
    queue = as_completed(futures)
    for future in queue:
        task = task_of.pop(future.key)
        state = pending.get(task.key)
        try:
            outcome = future.result()
        except Exception as error:  # noqa: BLE001 - a bug or a lost worker: report, commit nothing, go on
            if state is not None:
                failed.append(f"{task.path}: task on sets {task.start}..{task.stop - 1} failed: "
                              f"{type(error).__name__}: {error}")
                pending.pop(task.key)
            continue
        finally:
            future.release()
        if state is None:  # its recording already failed
            continue
        done_sets += task.sets
        state.outcomes[task.start] = outcome
        if len(state.outcomes) == state.tasks:
            if any(o.boundary_ok is False for o in state.outcomes.values()):
                logger.info("%s: an aperture boundary did not hold; analysing it as one task", task.path)
                done_sets -= state.plan.sets
                retry = whole_recording(state.plan)
                state.outcomes, state.tasks = {}, 1
                new = client.submit(analyse, retry, pure=False)  # type: ignore[attr-defined]
                task_of[new.key] = retry
                queue.add(new)
            else:
                rows, summary = assemble(state.plan, [state.outcomes[k] for k in sorted(state.outcomes)])
                summary = store.write_recording(f"{_stem(state.plan.path)}-{state.plan.key}", rows, summary)
                pending.pop(task.key)
                analysed.append(summary)
                on_recording(summary)
        on_progress(Progress(done_sets, total, len(analysed), len(plans), time.perf_counter() - start))
    return CampaignReport(tuple(analysed), tuple(resumed), tuple(failed))


def assemble(plan: RecordingPlan, outcomes: list[TaskOutcome]) -> tuple[list[ResultRow], RecordingSummary]:
    """One recording's rows from its blocks' outcomes (in order), and its summary.

    A later block's aperture ids count on from the earlier blocks' adoptions, and its results
    are marked ``affected_by_damage`` after a damaged set in an earlier block, as one replay of
    the whole recording would number and mark them.
    """
    rows: list[ResultRow] = []
    apertures_before, damage_before = 0, False
    for outcome in outcomes:
        rows.extend(renumbered(r, apertures_before, damage_before) if apertures_before or damage_before else r
                    for r in outcome.rows)
        apertures_before += sum(r.aperture_changed for r in outcome.rows)
        damage_before = damage_before or bool(outcome.skipped)
    damage = list(dict.fromkeys(d for o in outcomes for d in o.damage))
    notes = list(dict.fromkeys(n for o in outcomes for n in o.notes))
    error = next((o.error for o in outcomes if o.error), "")
    differences = [r.difference_rms for r in rows if not math.isnan(r.difference_rms)]
    stage = [sum(o.stage_s[i] for o in outcomes) for i in range(4)]
    status = "skipped" if error else ("damaged" if damage else "ok")
    summary = RecordingSummary(
        recording=plan.path, file_sha256=plan.file_sha256, settings_hash=plan.settings_hash, kind=plan.kind,
        status=status, sets=plan.sets, results=len(rows), valid=sum(r.valid for r in rows),
        skipped=sum(len(o.skipped) for o in outcomes), max_difference_rms=max(differences, default=math.nan),
        damage="; ".join(damage), notes="; ".join(notes), message=error, phase_s=stage[0], aperture_s=stage[1],
        unwrap_s=stage[2], fit_s=stage[3], wall_s=sum(o.wall_s for o in outcomes))
    return rows, summary


def _stem(path: str) -> str:
    name = path.replace("\\", "/").rsplit("/", 1)[-1]
    return name.rsplit(".", 1)[0] or "recording"

