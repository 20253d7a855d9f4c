"""Latency percentiles of a run from a fixed-size histogram, so a long run's memory stays flat.

:class:`LatencyHistogram` counts latencies in logarithmic bins, 1 % wide, from 1 us to 1000 s
(2083 bins of 8 bytes, about 16 KiB, however long the run). A percentile is read as the geometric
centre of the bin holding it, so it is within 0.5 % of the exact order statistic (within 1 us
below 1 us; values above 1000 s count in the top bin). The mean, minimum and maximum are exact.
"""

from __future__ import annotations

import math

import numpy as np

_LOW_MS = 1e-3  # 1 us
_HIGH_MS = 1e6  # 1000 s
_RATIO = 1.01  # bin width: 1 %
_BINS = math.ceil(math.log(_HIGH_MS / _LOW_MS) / math.log(_RATIO))


class LatencyHistogram:
    """Counts of latencies, ms, in fixed logarithmic bins (see the module notes for the precision).

    Examples
    --------
    >>> h = LatencyHistogram()
    >>> for ms in (10.0, 20.0, 30.0, 40.0):
    ...     h.add(ms)
    >>> abs(h.percentile(50) - 20.0) / 20.0 < 0.005, h.count
    (True, 4)
    """

    def __init__(self) -> None:
        self._counts = np.zeros(_BINS, dtype=np.int64)
        self.count = 0
        self.total_ms = 0.0
        self.min_ms = math.inf
        self.max_ms = -math.inf

    def add(self, latency_ms: float) -> None:
        """Count one latency, ms (a non-finite one is not counted)."""
        if not math.isfinite(latency_ms):
            return
        clipped = min(max(latency_ms, _LOW_MS), _HIGH_MS)
        index = min(_BINS - 1, int(math.log(clipped / _LOW_MS) / math.log(_RATIO)))
        self._counts[index] += 1
        self.count += 1
        self.total_ms += latency_ms
        self.min_ms, self.max_ms = min(self.min_ms, latency_ms), max(self.max_ms, latency_ms)

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100), ms, as the centre of its bin clamped to [min, max]; NaN when empty."""
        if self.count == 0:
            return math.nan
        rank = max(1, math.ceil(q / 100.0 * self.count))  # the rank-th smallest latency
        index = int(np.searchsorted(np.cumsum(self._counts), rank))
        centre = _LOW_MS * _RATIO ** (index + 0.5)
        return float(min(max(centre, self.min_ms), self.max_ms))
