"""The frame counters of the rings a camera replaced, so that its counters only grow over its life."""

from __future__ import annotations

import threading
from typing import TypeVar

from wavestack.drivers.ring import FrameRing, RingCounters

T = TypeVar("T")


class RingHistory:
    """The frame counters of the rings a camera replaced (on reopen, or after a reader gave up).

    A camera's counters are the replaced rings' plus the current ring's, so they only grow over the
    camera's life, across reconnects; a replaced ring's pending frames count as dropped.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._totals = (0, 0, 0, 0)  # acquired, delivered, dropped, dropped_in_gaps

    def replace(self, ring: FrameRing[T], name: str) -> FrameRing[T]:
        """A fresh ring like ``ring`` (named ``name``); ``ring``'s counts carry on, its pending frames dropped."""
        c = ring.counters()
        with self._lock:
            a, d, x, g = self._totals
            self._totals = (a + c.acquired, d + c.delivered, x + c.dropped + c.pending, g + c.dropped_in_gaps)
        return FrameRing(ring.capacity, ring.policy, name=name)

    def with_current(self, ring: FrameRing[T]) -> RingCounters:
        """The camera's frame counters: the replaced rings' and ``ring``'s."""
        c = ring.counters()
        with self._lock:
            a, d, x, g = self._totals
        return RingCounters(acquired=a + c.acquired, delivered=d + c.delivered, dropped=x + c.dropped,
                            dropped_in_gaps=g + c.dropped_in_gaps, pending=c.pending)
