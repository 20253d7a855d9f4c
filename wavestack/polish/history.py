"""A polishing campaign's runs as the loop kernel's history table: what the web view shows (pure).

A row per run in the order of :data:`POLISH_COLUMNS`; the trend is the surface RMS before the
first run, then after each run that was measured again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from wavestack.loop import Cell, LoopHistory
from wavestack.polish.run_record import RunRecord

__all__ = ["POLISH_COLUMNS", "campaign_history", "polish_row", "polish_trend"]

POLISH_COLUMNS = ("run", "job", "RMS before (nm)", "predicted RMS (nm)", "measured RMS (nm)", "ratio",
                  "dwell (s)", "machine")


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


def campaign_history(rows: Sequence[RunRecord]) -> LoopHistory:
    """The campaign's runs so far as a history table (a later row of the same run replaces an earlier one)."""
    latest = {row.run: row for row in rows}
    ordered = [latest[k] for k in sorted(latest)]
    return LoopHistory("polish", POLISH_COLUMNS, tuple(polish_row(r) for r in ordered), "surface RMS (nm)",
                       polish_trend(ordered))
