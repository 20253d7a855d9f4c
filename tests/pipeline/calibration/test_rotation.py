"""The N-position rotation test in the fitted basis: the turn of a coefficient vector, the separation of part and
reference except the orders kN, and the uncertainty of the answer."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import mode_list, zernike_basis
from wavestack.pipeline.calibration import angular_orders, rotate_coefficients, solve_rotation_test

MODES = tuple(mode_list("noll", 36))


def test_turning_the_coefficients_is_turning_the_figure() -> None:
    """Against the basis evaluated at turned coordinates: the figure turned by a at (u, v) is W(R(-a)(u, v))."""
    rng = np.random.default_rng(3)
    c = rng.standard_normal(len(MODES))
    u, v = rng.uniform(-0.7, 0.7, (2, 200))
    a = 0.61
    expected = zernike_basis(MODES, u * np.cos(a) + v * np.sin(a), v * np.cos(a) - u * np.sin(a)) @ c
    assert np.allclose(zernike_basis(MODES, u, v) @ rotate_coefficients(MODES, c, a), expected, atol=1e-10)
    with pytest.raises(ValueError, match="no \\(2, -2\\) partner"):
        rotate_coefficients([(0, 0), (2, 2)], [0.0, 1.0], 0.3)


def _figures(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    part = 0.05 * rng.standard_normal(len(MODES))
    reference = 0.03 * rng.standard_normal(len(MODES))
    return part, reference


def test_four_positions_separate_everything_but_the_symmetric_terms_and_the_orders_4k() -> None:
    rng = np.random.default_rng(11)
    part, reference = _figures(rng)
    angles = np.deg2rad([0.0, 90.2, 179.6, 270.3])  # stage read-backs, not exactly equal
    seen = np.array([rotate_coefficients(MODES, part, a) + reference for a in angles])
    solution = solve_rotation_test(MODES, seen, angles)
    orders = np.abs([m for _, m in MODES])
    separable = (orders % 4) != 0
    assert solution.unresolved_orders == angular_orders(MODES, 4) == (0, 4)
    assert np.array_equal(solution.resolved, separable)
    assert np.allclose(solution.part[separable], part[separable], atol=1e-12)
    assert np.allclose(solution.reference[separable], reference[separable], atol=1e-12)
    assert np.all(solution.part[~separable] == 0) and np.all(solution.reference[~separable] == 0)
    # the unresolved terms carry their sum, averaged over the positions (exact for m = 0)
    symmetric = orders == 0
    assert np.allclose(solution.unresolved[symmetric], (part + reference)[symmetric], atol=1e-12)


def test_the_stated_uncertainty_is_the_scatter_of_the_answer() -> None:
    """Positions measured with known noise: the part's error over 300 draws has the covariance the solver states."""
    rng = np.random.default_rng(5)
    part, reference = _figures(rng)
    angles = np.arange(4) * np.pi / 2
    sigma = 0.002
    covariances = np.broadcast_to(sigma**2 * np.eye(len(MODES)), (4, len(MODES), len(MODES)))
    clean = np.array([rotate_coefficients(MODES, part, a) + reference for a in angles])
    errors = []
    for _ in range(300):
        solution = solve_rotation_test(MODES, clean + sigma * rng.standard_normal(clean.shape), angles, covariances)
        errors.append(solution.part - np.where(solution.resolved, part, 0.0))
    resolved = solution.resolved
    spread = np.std(np.array(errors)[:, resolved], axis=0)
    # N = 4 equal positions: each part term is a mean of 4 rotated measurements, sigma / 2; 300 draws give the
    # spread to about 4 %
    assert np.allclose(solution.part_stderr[resolved], sigma / 2, rtol=1e-9)
    assert np.allclose(spread, solution.part_stderr[resolved], rtol=0.2)


def test_bad_input_is_named() -> None:
    with pytest.raises(ValueError, match="expected shape"):
        solve_rotation_test(MODES, np.zeros((3, 36)), np.zeros(4))
    with pytest.raises(ValueError, match="finite"):
        solve_rotation_test(MODES, np.full((2, 36), np.nan), np.zeros(2))
