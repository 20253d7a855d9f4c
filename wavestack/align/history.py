"""An alignment's iterations as the loop kernel's history table: what the web view shows (pure).

A row per iteration in the order of :data:`ALIGN_COLUMNS`; the trend is the worst field point's
RMS per iteration.
"""

from __future__ import annotations

from collections.abc import Sequence

from wavestack.align.loop import IterationRecord
from wavestack.loop import Cell, LoopHistory
from wavestack.pipeline.telescope import DOFS

__all__ = ["ALIGN_COLUMNS", "align_row", "align_trend", "alignment_history"]

ALIGN_COLUMNS = ("iteration", "worst RMS (waves)", "RMS per field point (waves)",
                 "estimate " + " ".join(DOFS) + " (mm, deg)", "move sent")


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


def alignment_history(records: Sequence[IterationRecord]) -> LoopHistory:
    """The iterations so far as a history table (a later record of the same iteration replaces an earlier one)."""
    latest = {record.iteration: record for record in records}
    ordered = [latest[k] for k in sorted(latest)]
    return LoopHistory("align", ALIGN_COLUMNS, tuple(align_row(r) for r in ordered), "worst field RMS (waves)",
                       align_trend(ordered))
