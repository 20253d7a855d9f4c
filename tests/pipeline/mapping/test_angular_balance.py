"""Angular area balancing: monotone, radius-preserving, and it equalises area over angle."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from wavestack.pipeline.mapping.angular_balance import balance_angles


def _ring_samples(rng: np.random.Generator, count: int = 4000):
    angle = rng.uniform(-np.pi, np.pi, count)
    radius = np.sqrt(rng.uniform(0.2, 1.0, count))
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)]), angle, radius


def test_uniform_area_is_left_nearly_alone() -> None:
    points, angle, _ = _ring_samples(np.random.default_rng(0))
    balanced = balance_angles(points, np.ones(len(points)))
    moved = np.angle(np.exp(1j * (np.arctan2(balanced[:, 1], balanced[:, 0]) - angle)))
    # the empirical area density of 4000 uniform samples deviates by ~1/sqrt(4000) per harmonic
    assert np.abs(moved).max() < 0.15


def test_lopsided_area_becomes_uniform_over_angle() -> None:
    points, angle, radius = _ring_samples(np.random.default_rng(1), 20000)
    area = 1.0 + 0.8 * np.cos(angle)  # nine times more area per radian on the +x side
    balanced = balance_angles(points, area)
    new_angle = np.arctan2(balanced[:, 1], balanced[:, 0])
    sectors = np.histogram(new_angle, bins=8, range=(-np.pi, np.pi), weights=area)[0]
    before = np.histogram(angle, bins=8, range=(-np.pi, np.pi), weights=area)[0]
    assert before.max() / before.min() > 5
    # Fejer smoothing keeps a bias of (1 - k/(K+1)) on the first harmonic: 11 % at K = 8
    assert sectors.max() / sectors.min() < 1.3
    np.testing.assert_allclose(np.hypot(*balanced.T), radius, rtol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    amplitudes=st.lists(st.floats(-0.95, 0.95), min_size=1, max_size=6),
    harmonics=st.integers(1, 16),
)
def test_reparametrisation_is_monotone_in_angle(amplitudes, harmonics) -> None:
    angle = np.linspace(-np.pi, np.pi, 2001)[:-1]
    density = 1.0 + sum(a * np.cos((k + 1) * angle) for k, a in enumerate(amplitudes)) / len(amplitudes)
    density = np.clip(density, 1e-3, None)  # any positive area density
    points = np.column_stack([np.cos(angle), np.sin(angle)])
    balanced = balance_angles(points, density, harmonics)
    new_angle = np.unwrap(np.arctan2(balanced[:, 1], balanced[:, 0]))
    assert np.all(np.diff(new_angle) > 0)  # Fejer weights: a non-negative smoothed density
    assert new_angle[-1] - new_angle[0] < 2 * np.pi


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="harmonics"):
        balance_angles(np.zeros((3, 2)), np.ones(3), 0)
    with pytest.raises(ValueError, match="canonical: expected shape"):
        balance_angles(np.zeros((3, 2)), np.ones(4))
