"""The summary's latency percentiles come from a fixed-size histogram: constant memory, 1 % bins."""

from __future__ import annotations

import math
import sys

import numpy as np

from wavestack.station.latency import LatencyHistogram


def test_percentiles_are_within_half_a_percent_of_the_exact_ones() -> None:
    latencies = np.random.default_rng(3).lognormal(3.0, 1.0, 20_000)
    histogram = LatencyHistogram()
    for ms in latencies:
        histogram.add(float(ms))
    for q in (1, 50, 90, 99, 100):
        exact = float(np.percentile(latencies, q, method="inverted_cdf"))
        assert abs(histogram.percentile(q) - exact) <= 0.005 * exact + 1e-9, q
    assert histogram.count == 20_000 and math.isclose(histogram.total_ms, latencies.sum())


def test_memory_does_not_grow_with_the_number_of_results() -> None:
    histogram = LatencyHistogram()
    size = sys.getsizeof(histogram._counts)
    for ms in np.linspace(0.5, 5000.0, 50_000):
        histogram.add(float(ms))
    assert sys.getsizeof(histogram._counts) == size < 20_000


def test_empty_and_out_of_range_latencies() -> None:
    histogram = LatencyHistogram()
    assert math.isnan(histogram.percentile(50))
    histogram.add(float("nan"))
    assert histogram.count == 0
    histogram.add(1e9)  # beyond the top bin: counted there, reported as the maximum seen at most
    histogram.add(1e-6)
    assert histogram.count == 2 and histogram.percentile(100) <= 1e9 and histogram.percentile(0) >= 1e-6
