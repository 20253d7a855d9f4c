"""What the station counts, in frames and in sets, each with an invariant that holds exactly.

A frame the camera produced ends up in a processed set, dropped, or pending (in a ring, or in the
hands of the thread assembling a phase-shifted set); a set the source assembled ends up
processed, dropped or pending. So, at every snapshot::

    frames acquired == frames in processed sets + frames dropped + frames pending
    sets assembled  == sets processed + sets dropped + sets pending

and, since every processed set holds ``frames_per_set`` frames, ``frames processed ==
frames_per_set x sets processed``. :class:`Counters` refuses to exist otherwise, so a count that
does not add up is a loud error where it is made, not a wrong number in a report. The counting
follows pylablib's frame counters (and :class:`~wavestack.drivers.ring.FrameRing`'s).

What a miscount does to a run (decided in issue 13): never a wrong number reported, never a dead
station. The station catches the ``ValueError`` where it takes a snapshot, logs it at ERROR, makes
that cycle's result invalid with the reason (``"counters: ..."``, so it is never sent to the PLC)
and reports the last snapshot that added up; the next cycle counts afresh. Since the counts of a
run only grow, a stale snapshot is an undercount, never a count that goes backwards.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


def _check_tally(unit: str, total_name: str, total: int, processed: int, dropped: int, pending: int) -> None:
    parts = {total_name: total, "processed": processed, "dropped": dropped, "pending": pending}
    negative = {name: value for name, value in parts.items() if value < 0}
    if negative:
        raise ValueError(f"{unit} counters: expected counts >= 0, got {negative}")
    if total != processed + dropped + pending:
        raise ValueError(f"{unit} counters do not add up: {total_name} {total} != processed {processed} + "
                         f"dropped {dropped} + pending {pending} (= {processed + dropped + pending})")


@dataclass(frozen=True)
class FrameCounts:
    """Frames: ``acquired == processed + dropped + pending`` (checked).

    Attributes
    ----------
    acquired : int
        Frames the camera produced, gaps in its frame ids included (a gap is a frame lost on the way).
    processed : int
        Frames in the sets the pipeline processed (valid results or not).
    dropped : int
        Frames given up: by the camera's ring, with a dropped set, in a set left unfinished by a
        device error, or pending when the camera was lost (a slow pipeline drops, never queues).
    pending : int
        Frames waiting: in the camera's ring, in sets waiting for the pipeline, or in the set being
        assembled.
    """

    acquired: int
    processed: int
    dropped: int
    pending: int

    def __post_init__(self) -> None:
        _check_tally("frame", "acquired", self.acquired, self.processed, self.dropped, self.pending)


@dataclass(frozen=True)
class SetCounts:
    """Sets (a phase-shifted set, or one carrier or spot frame): ``assembled == processed + dropped + pending``.

    Attributes
    ----------
    assembled : int
        Complete sets the source handed towards the pipeline.
    processed : int
        Sets the pipeline processed (one result each).
    dropped : int
        Sets given up by the newest-only ring, or pending when the camera was lost.
    pending : int
        Sets waiting for the pipeline.
    """

    assembled: int
    processed: int
    dropped: int
    pending: int

    def __post_init__(self) -> None:
        _check_tally("set", "assembled", self.assembled, self.processed, self.dropped, self.pending)


@dataclass(frozen=True)
class Counters:
    """Frames and sets so far, each adding up exactly, and tied together by the set size.

    Attributes
    ----------
    frames_per_set : int
        Frames in one set (5 for a five-step phase-shifted set, 1 for a carrier or spot frame).
    frames : FrameCounts
    sets : SetCounts

    Raises
    ------
    ValueError
        A count that does not add up, or frames processed that are not ``frames_per_set`` per
        processed set (and likewise frames dropped or pending fewer than in dropped or pending sets).

    Examples
    --------
    >>> c = Counters(5, FrameCounts(acquired=23, processed=10, dropped=8, pending=5),
    ...              SetCounts(assembled=4, processed=2, dropped=1, pending=1))
    >>> c.frames.acquired == c.frames.processed + c.frames.dropped + c.frames.pending
    True
    >>> Counters(5, FrameCounts(23, 2, 16, 5), SetCounts(4, 2, 1, 1))
    Traceback (most recent call last):
    ...
    ValueError: counters: 2 frames processed in 2 processed sets of 5; expected 10
    """

    frames_per_set: int
    frames: FrameCounts
    sets: SetCounts

    def __post_init__(self) -> None:
        n, frames, sets = self.frames_per_set, self.frames, self.sets
        if n < 1:
            raise ValueError(f"counters: frames_per_set must be >= 1, got {n}")
        if frames.processed != n * sets.processed:
            raise ValueError(f"counters: {frames.processed} frames processed in {sets.processed} processed sets "
                             f"of {n}; expected {n * sets.processed}")
        if frames.dropped < n * sets.dropped or frames.pending < n * sets.pending:
            raise ValueError(f"counters: frames dropped {frames.dropped} and pending {frames.pending} must cover "
                             f"the {sets.dropped} dropped and {sets.pending} pending sets of {n}")

    @classmethod
    def zero(cls, frames_per_set: int) -> Counters:
        """Nothing counted yet."""
        return cls(frames_per_set, FrameCounts(0, 0, 0, 0), SetCounts(0, 0, 0, 0))

    def plus(self, other: Counters) -> Counters:
        """Both counts together (e.g. a camera connection that was replaced, and the current one)."""
        if other.frames_per_set != self.frames_per_set:
            raise ValueError(f"counters: cannot add sets of {other.frames_per_set} frames to sets of "
                             f"{self.frames_per_set}")
        f, g, s, t = self.frames, other.frames, self.sets, other.sets
        return Counters(self.frames_per_set,
                        FrameCounts(f.acquired + g.acquired, f.processed + g.processed, f.dropped + g.dropped,
                                    f.pending + g.pending),
                        SetCounts(s.assembled + t.assembled, s.processed + t.processed, s.dropped + t.dropped,
                                  s.pending + t.pending))

    def retired(self) -> Counters:
        """The final counts of a source that will never deliver again: what was pending is dropped."""
        f, s = self.frames, self.sets
        return Counters(self.frames_per_set, FrameCounts(f.acquired, f.processed, f.dropped + f.pending, 0),
                        SetCounts(s.assembled, s.processed, s.dropped + s.pending, 0))

    def to_json(self) -> dict[str, object]:
        """``{"frames_per_set": n, "frames": {...}, "sets": {...}}`` as the JSON lines carry it."""
        return asdict(self)
