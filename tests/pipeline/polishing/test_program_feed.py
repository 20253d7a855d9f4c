"""The feed profile: the feed floor and the forward-backward acceleration pass, on cases worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fuzz import fuzz_settings
from wavestack.pipeline.polishing.feed import feed_profile, segment_lengths_mm


def test_a_crossed_point_between_long_dwells_is_limited_by_acceleration() -> None:
    # 1 mm moves, 0.5 mm/s^2 (2 a s = 1 mm^2/s^2), 100 mm/s allowed. Requests 10, 10, 0, 10, 10 s:
    # the long dwells run at 0.1 mm/s; the crossed point can only reach sqrt(0.1^2 + 1) mm/s.
    profile = feed_profile(np.array([10.0, 10.0, 0.0, 10.0, 10.0]), np.ones(5), 1.0, 100.0, 0.5)
    middle = math.sqrt(0.01 + 1.0)
    np.testing.assert_allclose(profile.feed_mm_s, [0.1, 0.1, middle, 0.1, 0.1], rtol=1e-6)
    assert profile.accel_points == 1
    assert profile.accel_extra_s == pytest.approx(1.0 / middle - 1.0 / 100.0, rel=1e-6)
    assert profile.floor_extra_s == pytest.approx(1.0 / 100.0, rel=1e-6)


def test_a_program_of_crossings_starts_and_ends_at_rest() -> None:
    # three 1 mm moves, nothing requested, 2 a s = 1: from rest 1, then sqrt 2, then (to stop
    # one step after the end) 1 mm/s
    profile = feed_profile(np.zeros(3), np.ones(3), 1.0, 100.0, 0.5)
    np.testing.assert_allclose(profile.feed_mm_s, [1.0, math.sqrt(2.0), 1.0], rtol=1e-6)
    np.testing.assert_allclose(profile.dwell_s, 1.0 / profile.feed_mm_s)


@fuzz_settings(200)
@given(
    requested=hnp.arrays(np.float64, st.integers(1, 60), elements=st.one_of(st.just(0.0), st.floats(1e-4, 10.0))),
    max_feed=st.floats(0.5, 500.0),
    max_accel=st.floats(0.1, 1e5),
    data=st.data(),
)
def test_the_profile_never_shortens_a_dwell_and_keeps_every_bound(
    requested: np.ndarray, max_feed: float, max_accel: float, data: st.DataObject
) -> None:
    segment = data.draw(hnp.arrays(np.float64, requested.shape, elements=st.floats(0.01, 2.0)))
    profile = feed_profile(requested, segment, 0.5, max_feed, max_accel)
    v, t = profile.feed_mm_s, profile.dwell_s
    assert np.all(t >= requested) and np.all(v <= max_feed)
    np.testing.assert_allclose(v * t, segment, rtol=1e-12)
    v2 = np.concatenate(([0.0], v * v, [0.0]))
    gain = 2 * max_accel * np.concatenate((segment, [0.5]))
    assert np.all(np.abs(np.diff(v2)) <= gain * (1 + 1e-9))
    assert profile.floor_extra_s >= 0 and profile.accel_extra_s >= 0
    assert t.sum() == pytest.approx(requested.sum() + profile.floor_extra_s + profile.accel_extra_s, rel=1e-9)


def test_segment_lengths_start_with_the_step() -> None:
    lengths = segment_lengths_mm(np.array([0.0, 3.0, 3.0]), np.array([0.0, 4.0, 5.0]), 0.25)
    assert lengths.tolist() == [0.25, 5.0, 1.0]
    assert segment_lengths_mm(np.zeros(0), np.zeros(0), 1.0).size == 0
