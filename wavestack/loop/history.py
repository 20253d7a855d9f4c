"""A loop's history as a table of plain values: what the web view, the terminal and the figures read.

A loop's records (a polishing campaign's runs, an alignment's iterations) are the loop's own
frozen values; what a reader above the loops needs is only a table: column names, rows of plain
numbers and words, and one figure per measurement for a small trend chart. :class:`LoopHistory`
is that table; each loop builds it from its records (``wavestack.polish.campaign_history``,
``wavestack.align.alignment_history``), so nothing above the loops imports them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

__all__ = ["Cell", "LoopHistory"]

#: One cell: a number (None when not known yet) or a word.
Cell = Union[int, float, str, None]


@dataclass(frozen=True)
class LoopHistory:
    """A loop's history table (module notes).

    Attributes
    ----------
    kind : str
        The loop (``"polish"``, ``"align"``).
    columns : tuple of str
    rows : tuple of tuples of Cell
        One row per run or iteration, in order, each in the order of ``columns``.
    trend_label : str
        What the trend is, with its unit.
    trend : tuple of float
        One figure per measurement.

    Example
    -------
    >>> LoopHistory("align", ("iteration", "worst RMS (waves)"), ((0, 0.3),), "worst RMS (waves)", (0.3,)).rows[0][1]
    0.3
    """

    kind: str
    columns: tuple[str, ...]
    rows: tuple[tuple[Cell, ...], ...]
    trend_label: str
    trend: tuple[float, ...]
