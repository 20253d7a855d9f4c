"""The alignment run's record: the configuration, every transition and iteration, how it ended.

Format ``wavestack-align`` on the loop kernel's checksummed record (:mod:`~wavestack.loop.record`,
version 2: a CRC-32 per record, flushed per record, an existing file never overwritten). Header:
the degrees of freedom (``dofs``) and the field points (``field_points_deg``). Records, in order:
``event`` (every transition with its reason), ``iteration`` (its RMS per field point, waves, and
when the iteration corrected: the estimate X Y Z mm, U V deg, the move sent and the position read
back, each an axis -> value mapping), ``end`` (final phase, reason, iterations done, whether the
hexapod halted: ``true``, ``false`` or ``null`` when it was never asked to). A run that ends by a
crash keeps what it measured; :func:`read_alignment` reads back every intact record.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.align.loop import AlignSummary, IterationRecord
from wavestack.loop import CampaignWriter, read_campaign
from wavestack.pipeline.telescope import DOFS

__all__ = ["FORMAT_NAME", "AlignRecorder", "RecordedAlignment", "read_alignment"]

FORMAT_NAME = "wavestack-align"


class AlignRecorder:
    """Record an alignment run (module notes).

    Parameters
    ----------
    path : Path
        A new file (checked by the caller).
    config_text : str
    field_points_deg : sequence of (float, float)

    Examples
    --------
    >>> import tempfile
    >>> folder = tempfile.mkdtemp()
    >>> recorder = AlignRecorder(Path(folder) / "a.h5", "", [(0.0, 0.0)])
    >>> recorder.iteration(IterationRecord(0, (0.05,)))
    >>> recorder.close("target-met", "done", 0, None)
    >>> run = read_alignment(Path(folder) / "a.h5")
    >>> run.ending["final_phase"], run.iterations[0].rms_waves
    ('target-met', (0.05,))
    """

    def __init__(self, path: Path, config_text: str, field_points_deg: Sequence[tuple[float, float]], *,
                 software_version: str = "") -> None:
        header = {"dofs": list(DOFS), "field_points_deg": [list(map(float, f)) for f in field_points_deg]}
        self._writer = CampaignWriter(Path(path), FORMAT_NAME, config_text, header, software_version=software_version)

    def event(self, phase: str, reason: str) -> None:
        """One transition (the loop's ``recorder``)."""
        self._writer.event(phase, reason)

    def iteration(self, record: IterationRecord) -> None:
        """Append one iteration and flush."""
        self._writer.append("iteration", {"iteration": record.iteration, "rms_waves": list(record.rms_waves),
                                          "estimate": None if record.estimate is None else list(record.estimate),
                                          "move": record.move, "read_back": record.read_back})

    def close(self, phase: str, reason: str, iterations_done: int, halted: bool | None) -> None:
        """Write how the run ended and close (idempotent: the first close's ending is the one kept)."""
        self._writer.close({"final_phase": phase, "reason": reason, "iterations_done": int(iterations_done),
                            "halted": halted})

    def finish(self, summary: AlignSummary) -> None:
        """:meth:`close` with a summary's ending."""
        self.close(summary.state.phase.value, summary.state.reason or "", summary.state.iterations_done,
                   summary.halted)


@dataclass(frozen=True, eq=False)
class RecordedAlignment:
    """An alignment record as read back: header, every intact iteration and transition, the ending, the damage."""

    header: dict[str, Any]
    config_text: str
    iterations: tuple[IterationRecord, ...]
    events: tuple[tuple[str, str], ...]
    ending: dict[str, Any] | None
    damage: tuple[str, ...]


def _iteration(fields: dict[str, Any]) -> IterationRecord:
    estimate = fields.get("estimate")
    return IterationRecord(int(fields["iteration"]), tuple(float(r) for r in fields["rms_waves"]),
                           None if estimate is None else tuple(float(v) for v in estimate), fields.get("move"),
                           fields.get("read_back"))


def read_alignment(path: Path) -> RecordedAlignment:
    """Read an alignment record: every intact record, the damaged ones named.

    Raises
    ------
    InputError
        Not an alignment record, or unreadable as a whole.
    """
    log = read_campaign(Path(path), FORMAT_NAME)
    endings = log.of_kind("end")
    return RecordedAlignment(dict(log.header), log.config_text,
                             tuple(_iteration(dict(e.fields)) for e in log.of_kind("iteration")),
                             tuple((str(e.fields["phase"]), str(e.fields["reason"])) for e in log.of_kind("event")),
                             dict(endings[-1].fields) if endings else None, log.damage)
