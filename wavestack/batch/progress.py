"""Campaign progress as a value (sets done, rate, time left) and its two renderings: a terminal
bar and a JSON object. Pure: the CLI writes them."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Progress:
    """Where a campaign stands.

    Attributes
    ----------
    sets_done, sets_total : int
        Sets (or maps) analysed or skipped so far, and in the whole campaign.
    recordings_done, recordings_total : int
    elapsed_s : float
        Seconds since the first task was submitted.

    Example
    -------
    >>> p = Progress(50, 200, 1, 4, 10.0)
    >>> p.rate_sets_per_s, p.eta_s
    (5.0, 30.0)
    """

    sets_done: int
    sets_total: int
    recordings_done: int
    recordings_total: int
    elapsed_s: float

    @property
    def rate_sets_per_s(self) -> float:
        return self.sets_done / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def eta_s(self) -> float:
        """Seconds left at the rate so far (NaN before the first set)."""
        rate = self.rate_sets_per_s
        return (self.sets_total - self.sets_done) / rate if rate > 0 else math.nan

    def to_json(self) -> dict[str, object]:
        eta = self.eta_s
        return {"type": "progress", "sets_done": self.sets_done, "sets_total": self.sets_total,
                "recordings_done": self.recordings_done, "recordings_total": self.recordings_total,
                "elapsed_s": round(self.elapsed_s, 3), "rate_sets_per_s": round(self.rate_sets_per_s, 3),
                "eta_s": None if math.isnan(eta) else round(eta, 1)}


def progress_bar(p: Progress, width: int = 30) -> str:
    """One terminal line, e.g. ``[#######.......] 120/480 sets  2/8 recordings  35.2 sets/s  0:10 left``.

    Example
    -------
    >>> progress_bar(Progress(5, 10, 0, 1, 1.0), width=10)
    '[#####.....] 5/10 sets  0/1 recordings  5.0 sets/s  0:01 left'
    """
    fraction = p.sets_done / p.sets_total if p.sets_total else 1.0
    filled = int(round(width * min(1.0, fraction)))
    eta = p.eta_s
    left = "--:-- left" if math.isnan(eta) else f"{_clock(eta)} left"
    return (f"[{'#' * filled}{'.' * (width - filled)}] {p.sets_done}/{p.sets_total} sets  "
            f"{p.recordings_done}/{p.recordings_total} recordings  {p.rate_sets_per_s:.1f} sets/s  {left}")


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"
