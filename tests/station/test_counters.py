"""Frame and set counters as values: each adds up exactly, or the value refuses to exist."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wavestack.station import Counters, FrameCounts, SetCounts


def _counters(fps: int, sets: tuple[int, int, int], extra_dropped: int, extra_pending: int) -> Counters:
    processed, dropped, pending = sets
    return Counters(fps, FrameCounts(fps * (processed + dropped + pending) + extra_dropped + extra_pending,
                                     fps * processed, fps * dropped + extra_dropped, fps * pending + extra_pending),
                    SetCounts(processed + dropped + pending, processed, dropped, pending))


def test_counts_that_add_up_are_kept_and_carried_as_json() -> None:
    # five-step sets: 4 assembled (2 processed, 1 dropped, 1 pending); 3 frames more dropped by the
    # camera ring, 2 more pending in the set being assembled
    c = _counters(5, (2, 1, 1), 3, 2)
    assert c.frames == FrameCounts(acquired=25, processed=10, dropped=8, pending=7)
    assert c.to_json() == {"frames_per_set": 5,
                           "frames": {"acquired": 25, "processed": 10, "dropped": 8, "pending": 7},
                           "sets": {"assembled": 4, "processed": 2, "dropped": 1, "pending": 1}}
    assert Counters.zero(5).frames == FrameCounts(0, 0, 0, 0)


@pytest.mark.parametrize("make, message", [
    (lambda: FrameCounts(161, 20, 60, 0), "161 != processed 20 + dropped 60 + pending 0"),  # the run
    (lambda: SetCounts(4, 2, 1, 0), "assembled 4 != processed 2"),
    (lambda: FrameCounts(5, 6, -1, 0), "expected counts >= 0"),
    # the units mix-up: frames processed counted in sets
    (lambda: Counters(5, FrameCounts(161, 20, 60, 81), SetCounts(20, 20, 0, 0)), "expected 100"),
    (lambda: Counters(5, FrameCounts(20, 10, 4, 6), SetCounts(4, 2, 1, 1)), "must cover"),
    (lambda: Counters(0, FrameCounts(0, 0, 0, 0), SetCounts(0, 0, 0, 0)), "frames_per_set"),
])
def test_counts_that_do_not_add_up_are_refused(make, message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("+", r"\+")):
        make()


counts = st.tuples(st.integers(0, 50), st.integers(0, 50), st.integers(0, 50))


@given(st.integers(1, 8), counts, counts, st.integers(0, 9), st.integers(0, 9))
def test_plus_and_retired_keep_the_invariants(fps: int, a: tuple[int, int, int], b: tuple[int, int, int],
                                              extra_dropped: int, extra_pending: int) -> None:
    first, second = _counters(fps, a, extra_dropped, extra_pending), _counters(fps, b, extra_pending, extra_dropped)
    total = first.plus(second)  # constructing it checks every invariant again
    assert total.frames.acquired == first.frames.acquired + second.frames.acquired
    assert total.sets.processed == a[0] + b[0]
    retired = first.retired()
    assert retired.frames.pending == retired.sets.pending == 0
    assert retired.frames.dropped == first.frames.dropped + first.frames.pending
    assert retired.frames.processed == first.frames.processed and retired.sets.assembled == first.sets.assembled


def test_sets_of_different_sizes_do_not_add() -> None:
    with pytest.raises(ValueError, match="cannot add"):
        Counters.zero(5).plus(Counters.zero(1))
