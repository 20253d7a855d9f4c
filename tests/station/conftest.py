"""What every station test may check about a run's frame and set counters."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import pytest

from wavestack.station import Counters, CycleRecord


def _check_counts(records: Sequence[CycleRecord], frames_per_set: int, *, ids_from_zero: bool = True) -> Counters:
    """Assert the counters of every result add up exactly and agree with the sets the test saw.

    Sets and frames processed are counted here from the records themselves; with
    ``ids_from_zero`` (one camera connection whose frame ids start at 0), every frame up to the
    newest processed one is processed or dropped (newest-only rings), so processed + dropped
    reaches past the newest frame id. Returns the last result's counters.
    """
    sets = frames = 0
    newest_id = -1
    previous: Counters | None = None
    for record in records:
        c = record.result.counters
        if record.frames:
            sets += 1
            frames += len(record.frames)
            newest_id = max(newest_id, *(f.frame_id for f in record.frames))
        f, s = c.frames, c.sets
        assert c.frames_per_set == frames_per_set
        assert f.acquired == f.processed + f.dropped + f.pending, f
        assert s.assembled == s.processed + s.dropped + s.pending, s
        assert (s.processed, f.processed) == (sets, frames), (c, sets, frames)
        if ids_from_zero:
            assert f.acquired >= newest_id + 1 and f.processed + f.dropped >= newest_id + 1, (c, newest_id)
        if previous is not None:  # counts only grow, also across a camera reconnect
            p = previous
            assert f.acquired >= p.frames.acquired and f.dropped >= p.frames.dropped, (p, c)
            assert s.assembled >= p.sets.assembled and s.dropped >= p.sets.dropped, (p, c)
        previous = c
    assert previous is not None
    return previous


@pytest.fixture
def check_counts() -> Callable[..., Counters]:
    """:func:`_check_counts`, for the station tests."""
    return _check_counts
