"""Robust averaging in the fitted basis: rejection of corrupted maps, standard errors that cover the truth."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import build_fitter
from wavestack.pipeline.averaging import TooFewMeasurements, robust_average

SIZE = 32
MODES = 10
NOISE_WAVES = 0.01  # per-pixel measurement noise of a clean map


def _disk() -> np.ndarray:
    rows, cols = np.indices((SIZE, SIZE))
    return (rows - 15.5) ** 2 + (cols - 15.5) ** 2 <= 14.5**2


def _corrupted_set(rng: np.random.Generator, count: int = 20) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """``count`` maps of one surface with noise; map 3 has a vibration burst, map 11 a fringe-order jump."""
    mask = _disk()
    fitter = build_fitter(mask, "circle", MODES, dtype=np.float64)
    truth = np.array([0.0, 0.05, -0.03, 0.2, 0.04, -0.06, 0.02, 0.01, -0.015, 0.03])
    surface = fitter.surface(truth)
    maps = surface + NOISE_WAVES * rng.standard_normal((count, SIZE, SIZE))
    rows, cols = np.indices((SIZE, SIZE))
    # a vibration burst during a phase-shifting set prints a ripple at twice the fringe frequency
    maps[3] += 0.08 * np.sin(2 * np.pi * cols / 6.0 + 0.7)
    maps[11] += np.where(rows > 20, 1.0, 0.0)  # a fringe-order jump: one wave over a band of the map
    maps[:, ~mask] = np.nan
    coefficients = np.array([fitter.fit(m).coefficients for m in maps])
    return coefficients, maps, (3, 11)


def test_corrupted_maps_are_rejected_by_index_and_the_average_is_the_clean_one() -> None:
    coefficients, maps, corrupted = _corrupted_set(np.random.default_rng(7))
    average = robust_average(coefficients, maps)
    assert average.rejected == corrupted
    assert average.count == 18
    clean = np.delete(np.arange(20), corrupted)
    clean_coefficients = coefficients[clean].mean(axis=0)
    # the robust average equals the clean average within its standard error (identical here when the
    # rejection is exact; the bound is what the issue asks)
    assert np.all(np.abs(average.coefficients - clean_coefficients) <= average.coefficient_stderr)
    clean_map = maps[clean].mean(axis=0)
    inside = _disk()
    assert np.all(np.abs(average.map - clean_map)[inside] <= average.map_stderr[inside])
    # and the plain mean does not: the corrupted maps move it by many standard errors
    naive = coefficients.mean(axis=0)
    assert np.max(np.abs(naive - clean_coefficients) / average.coefficient_stderr) > 5
    assert np.all(np.isnan(average.map[~inside])) and np.all(np.isnan(average.map_stderr[~inside]))
    # the per-pixel standard error is the map noise over sqrt(n), within its own sampling spread
    assert np.median(average.map_stderr[inside]) == pytest.approx(NOISE_WAVES / np.sqrt(18), rel=0.15)
    assert np.allclose(np.diag(average.coefficient_covariance), average.coefficient_stderr**2)


def test_one_sigma_coefficient_errors_cover_the_truth_in_about_68_percent_of_200_trials() -> None:
    """Coefficient-only (the rule and the errors use nothing else): 20 measurements of 6 terms, 10 % corrupted.

    For n = 18 kept normal measurements the mean lies within one standard error of the truth with the
    probability of |t_17| < 1, 0.669; 200 trials of 6 terms (1200, partly correlated draws) give it to
    about +-2 %, inside the issue's 60-76 %.
    """
    truth = np.array([0.0, 0.3, -0.2, 0.1, 0.05, -0.04])
    sigma = np.array([0.01, 0.02, 0.02, 0.005, 0.01, 0.03])
    covered = []
    for trial in range(200):
        rng = np.random.default_rng(1000 + trial)
        values = truth + sigma * rng.standard_normal((20, truth.size))
        bad = rng.choice(20, size=2, replace=False)
        values[bad[0]] += 40 * sigma * rng.standard_normal(truth.size)  # burst: all terms thrown
        values[bad[1], 1:3] += [1.0, -1.0]  # a jump moving the tilts
        average = robust_average(values)
        assert set(average.rejected) >= set(bad.tolist())
        covered.append(np.abs(average.coefficients - truth) <= average.coefficient_stderr)
    fraction = float(np.mean(covered))
    assert 0.60 <= fraction <= 0.76, fraction


def test_a_constant_coefficient_rejects_nothing_and_bad_input_is_named() -> None:
    values = np.column_stack([np.zeros(6), np.linspace(0.0, 1e-3, 6)])
    assert robust_average(values).rejected == ()
    with pytest.raises(ValueError, match="coefficients: expected shape"):
        robust_average(np.zeros(5))
    with pytest.raises(ValueError, match="finite"):
        robust_average(np.array([[0.0], [np.nan], [1.0]]))
    with pytest.raises(ValueError, match="maps: expected shape"):
        robust_average(np.zeros((4, 2)), np.zeros((3, 5, 5)))
    with pytest.raises(TooFewMeasurements, match="2 measurements, at least 3"):
        robust_average(np.zeros((2, 2)))
    many_off = np.array([[0.0], [0.0], [0.0], [0.0], [5.0], [6.0], [7.0]])
    with pytest.raises(TooFewMeasurements, match="3 of 7 measurements rejected"):
        robust_average(many_off, min_kept=5)
