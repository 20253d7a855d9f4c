"""A polishing campaign's runs and an alignment's iterations as the web view's history table (pure).

A row is a tuple of plain numbers and words in the order of its table's columns; the trend is
one figure per measurement for the page's small chart: the surface RMS before the first run and
after each run (polish), the worst field point's RMS per iteration (align).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from wavestack.align.loop import IterationRecord
from wavestack.pipeline.telescope import DOFS
from wavestack.polish.run_record import RunRecord
from wavestack.web.view import Cell

__all__ = ["ALIGN_COLUMNS", "POLISH_COLUMNS", "align_row", "align_trend", "polish_row", "polish_trend"]

POLISH_COLUMNS = ("run", "job", "RMS before (nm)", "predicted RMS (nm)", "measured RMS (nm)", "ratio",
                  "dwell (s)", "machine")
ALIGN_COLUMNS = ("iteration", "worst RMS (waves)", "RMS per field point (waves)",
                 "estimate " + " ".join(DOFS) + " (mm, deg)", "move sent")


def _number(value: float) -> float | None:
    return value if math.isfinite(value) else None


def polish_row(row: RunRecord) -> tuple[Cell, ...]:
    """One run as a row of :data:`POLISH_COLUMNS`.

    Example
    -------
    >>> from wavestack.polish.run_record import run_started
    >>> row = run_started(1, 7, rms_before_nm=40.0, pv_before_nm=200.0, noise_before_nm=0.2, predicted_rms_nm=4.0,
    ...                   predicted_pv_nm=30.0, total_dwell_s=900.0, points=4000, job_crc32=1, started_unix_s=0.0,
    ...                   solve_s=1.0)
    >>> polish_row(row)[:5]
    (1, 7, 40.0, 4.0, None)
    """
    machine = f"{row.machine_state} {row.points_done}/{row.points}" if row.machine_state else "-"
    return (row.run, row.job_id, _number(row.rms_before_nm), _number(row.predicted_rms_nm),
            _number(row.measured_rms_nm), _number(row.convergence_ratio), _number(row.total_dwell_s), machine)


def polish_trend(rows: Sequence[RunRecord]) -> tuple[float, ...]:
    """Surface RMS (nm) before the first run, then after each run that was measured again."""
    if not rows:
        return ()
    after = [row.measured_rms_nm for row in rows if math.isfinite(row.measured_rms_nm)]
    return (rows[0].rms_before_nm, *after)


def _axes(values: dict[str, float] | None) -> str:
    return "-" if values is None else " ".join(f"{axis}={value:+.4f}" for axis, value in values.items())


def align_row(record: IterationRecord) -> tuple[Cell, ...]:
    """One iteration as a row of :data:`ALIGN_COLUMNS`.

    Example
    -------
    >>> align_row(IterationRecord(0, (0.2, 0.3)))[:3]
    (0, 0.3, '0.2000 0.3000')
    """
    estimate = "-" if record.estimate is None else " ".join(f"{v:+.4f}" for v in record.estimate)
    worst = max(record.rms_waves) if record.rms_waves else None
    return (record.iteration, worst, " ".join(f"{r:.4f}" for r in record.rms_waves), estimate, _axes(record.move))


def align_trend(records: Sequence[IterationRecord]) -> tuple[float, ...]:
    """The worst field point's RMS per iteration, waves."""
    return tuple(max(r.rms_waves) for r in records if r.rms_waves)
