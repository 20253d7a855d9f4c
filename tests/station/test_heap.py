"""Freed heap memory goes back to the system at most once per period, and never where it cannot."""

from __future__ import annotations

import pytest

from wavestack.station.heap import HeapRelease, glibc_malloc_trim


def test_trims_at_most_once_per_period() -> None:
    calls: list[float] = []
    release = HeapRelease(2.0, trim=lambda: calls.append(1.0))
    done = [release.maybe_release(t) for t in (10.0, 10.5, 11.9, 12.0, 13.0, 14.5)]
    assert done == [True, False, False, True, False, True]
    assert len(calls) == 3


def test_after_a_fault_cycles_are_collected_then_the_heap_trimmed_as_this_periods_trim() -> None:
    events: list[str] = []
    release = HeapRelease(2.0, trim=lambda: events.append("trim"), collect=lambda: events.append("collect"))
    release.after_fault(10.0)
    assert events == ["collect", "trim"]
    assert [release.maybe_release(t) for t in (11.0, 12.0)] == [False, True]


def test_after_a_fault_cycles_are_collected_also_without_trimming() -> None:
    events: list[str] = []
    release = HeapRelease(0.0, trim=lambda: events.append("trim"), collect=lambda: events.append("collect"))
    release.after_fault(1.0)
    assert events == ["collect"]


def test_a_zero_period_never_trims() -> None:
    calls: list[int] = []
    release = HeapRelease(0.0, trim=lambda: calls.append(1))
    assert not any(release.maybe_release(t) for t in (0.0, 1.0, 100.0))
    assert calls == []


@pytest.mark.parametrize("period", [-1.0, float("nan")])
def test_a_negative_or_nan_period_is_refused(period: float) -> None:
    with pytest.raises(ValueError, match="period_s"):
        HeapRelease(period, trim=lambda: None)


def test_glibc_trim_runs_where_the_c_library_has_it() -> None:
    trim = glibc_malloc_trim()
    if trim is None:  # musl or another C library: the station then never trims, which the class handles
        assert HeapRelease(1.0).maybe_release(0.0) is False
    else:
        trim()  # returns nothing, raises nothing
        assert HeapRelease(1.0).maybe_release(0.0) is True
