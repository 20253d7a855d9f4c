"""Tests for the annular Zernike polynomials (Mahajan 1981, 1994)."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.zernike.annular import annular_radial, annular_zernike_basis, annular_zernike_gradient
from wavestack.pipeline.zernike.circle import zernike_basis, zernike_gradient, zernike_radial

MODES_12 = [(n, m) for n in range(13) for m in range(-n, n + 1, 2)]
MODES_20 = [(n, m) for n in range(21) for m in range(-n, n + 1, 2)]
OBSCURATIONS = (0.1, 0.35, 0.6)


def annulus_points(eps: float, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    radius = np.sqrt(rng.uniform(eps**2, 1.0, count))  # uniform over the annulus area
    angle = rng.uniform(0.0, 2.0 * np.pi, count)
    return radius * np.cos(angle), radius * np.sin(angle)


@pytest.mark.parametrize("eps", OBSCURATIONS)
def test_orthonormal_over_the_annulus(eps: float) -> None:
    # Gauss-Legendre in rho on [eps, 1] with 16 nodes is exact to degree 31 >= 2*12 + 1;
    # the theta trapezoid with 32 points is exact for frequencies < 32 (products reach 24).
    nodes, weights = np.polynomial.legendre.leggauss(16)
    half = 0.5 * (1.0 - eps)
    rho = 0.5 * (1.0 + eps) + half * nodes
    angles = 2.0 * np.pi * np.arange(32) / 32
    r_grid, t_grid = np.meshgrid(rho, angles, indexing="ij")
    w = ((half * weights * rho)[:, None] * np.full(32, 2.0 * np.pi / 32)).ravel()
    x, y = (r_grid * np.cos(t_grid)).ravel(), (r_grid * np.sin(t_grid)).ravel()
    basis = annular_zernike_basis(MODES_12, x, y, eps)
    gram = basis.T @ (w[:, None] * basis) / (np.pi * (1.0 - eps**2))  # mean over the area
    # Exact quadrature, so only rounding remains (measured ~1e-14).
    np.testing.assert_allclose(gram, np.eye(len(MODES_12)), rtol=0, atol=1e-10)


def test_equal_to_circle_polynomials_at_zero_obscuration() -> None:
    x, y = annulus_points(0.0, 60, seed=1)
    x[0], y[0] = 0.0, 0.0
    # Both are evaluated by different recurrences (Stieltjes vs Shakibaei-Paramesran);
    # values reach ~sqrt(42) * few, rounding differences measured 4e-14.
    np.testing.assert_allclose(
        annular_zernike_basis(MODES_20, x, y, 0.0), zernike_basis(MODES_20, x, y), atol=1e-11
    )
    annular_grad = annular_zernike_gradient(MODES_20, x, y, 0.0)
    circle_grad = zernike_gradient(MODES_20, x, y)
    for got, expected in zip(annular_grad, circle_grad):
        # Gradients are up to ~n^2 larger than the values; measured difference 3e-12.
        np.testing.assert_allclose(got, expected, atol=1e-9)


def test_continuous_as_obscuration_goes_to_zero() -> None:
    x, y = annulus_points(0.0, 60, seed=2)
    near = annular_zernike_basis(MODES_20, x, y, 1e-6)
    at_zero = annular_zernike_basis(MODES_20, x, y, 0.0)
    # The polynomials depend smoothly on eps^2 = 1e-12 with derivatives of order n^2 times
    # the values, so the change is ~1e-12 * 400 * 6 ~ 3e-9 at most (measured 7e-11).
    np.testing.assert_allclose(near, at_zero, atol=1e-8)


@pytest.mark.parametrize("eps", (*OBSCURATIONS, 0.9))
def test_mahajan_closed_forms(eps: float) -> None:
    rho = np.linspace(eps, 1.0, 9)
    e2 = eps**2
    closed = {
        (1, 1): rho / np.sqrt(1 + e2),
        (2, 0): (2 * rho**2 - 1 - e2) / (1 - e2),
        (2, 2): rho**2 / np.sqrt(1 + e2 + e2**2),
        (3, 1): (3 * (1 + e2) * rho**3 - 2 * (1 + e2 + e2**2) * rho)
        / ((1 - e2) * np.sqrt((1 + e2) * (1 + 4 * e2 + e2**2))),
        (4, 0): (6 * rho**4 - 6 * (1 + e2) * rho**2 + 1 + 4 * e2 + e2**2) / (1 - e2) ** 2,
    }
    for (n, m), expected in closed.items():
        # Values are O(1); a handful of roundings in each evaluation.
        np.testing.assert_allclose(annular_radial(n, m, rho, eps), expected, atol=1e-13)
        np.testing.assert_array_equal(
            annular_radial(n, -m, rho, eps), annular_radial(n, m, rho, eps)
        )


@pytest.mark.parametrize("eps", (*OBSCURATIONS, 0.9))
def test_rotationally_symmetric_closed_form(eps: float) -> None:
    # Mahajan (1981): R_n^0(rho; eps) = R_n^0(sqrt((rho^2 - eps^2) / (1 - eps^2))).
    rho = np.linspace(eps, 1.0, 13)
    mapped = np.sqrt((rho**2 - eps**2) / (1 - eps**2))
    for n in range(0, 21, 2):
        # Both sides are O(1) on the annulus; measured differences ~1e-14.
        np.testing.assert_allclose(
            annular_radial(n, 0, rho, eps), zernike_radial(n, 0, mapped), atol=1e-12
        )


@pytest.mark.parametrize("eps", (*OBSCURATIONS, 0.9))
def test_edge_value(eps: float) -> None:
    # Sign convention: R(1; eps) > 0 for every mode.  Mahajan's "R(1; eps) = 1" holds with
    # the unit-RMS normalisation only for m = 0; for m != 0 it is below 1 (e.g. tilt
    # 1/sqrt(1 + eps^2)), which this test records as a measured fact for n <= 20.
    for n in range(21):
        for m in range(n % 2, n + 1, 2):
            edge = float(annular_radial(n, m, 1.0, eps))
            assert edge > 0.0, (n, m)
            if m == 0:
                assert edge == pytest.approx(1.0, abs=1e-12), n
            else:
                assert edge < 1.0, (n, m)


@pytest.mark.parametrize("eps", (0.35, 0.6))
def test_gradient_matches_finite_differences(eps: float) -> None:
    x, y = annulus_points(eps, 40, seed=5)
    x[0], y[0] = 0.0, 0.0  # the origin (outside the annulus, still a polynomial)
    dzdx, dzdy = annular_zernike_gradient(MODES_12, x, y, eps)
    assert np.all(np.isfinite(dzdx)) and np.all(np.isfinite(dzdy))
    step = 1e-4

    def basis(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return annular_zernike_basis(MODES_12, u, v, eps)

    fd_x = (-basis(x + 2 * step, y) + 8 * basis(x + step, y)
            - 8 * basis(x - step, y) + basis(x - 2 * step, y)) / (12 * step)  # fmt: skip
    fd_y = (-basis(x, y + 2 * step) + 8 * basis(x, y + step)
            - 8 * basis(x, y - step) + basis(x, y - 2 * step)) / (12 * step)  # fmt: skip
    # Fourth-order differences: truncation ~h^4 |f^(5)| and rounding ~u |f| / h, measured
    # ~5e-10 for gradients up to ~200; the bound scales with the largest gradient.
    tolerance = 1e-8 * (1.0 + max(np.abs(dzdx).max(), np.abs(dzdy).max()))
    np.testing.assert_allclose(dzdx, fd_x, rtol=0, atol=tolerance)
    np.testing.assert_allclose(dzdy, fd_y, rtol=0, atol=tolerance)


@pytest.mark.parametrize("eps", [-0.1, 1.0, 1.5, float("nan"), float("inf"), "0.3", None, True])
def test_invalid_obscuration_raises(eps: object) -> None:
    with pytest.raises(ValueError, match="obscuration"):
        annular_radial(2, 0, [0.5], eps)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="obscuration"):
        annular_zernike_basis([(2, 0)], [0.5], [0.0], eps)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="obscuration"):
        annular_zernike_gradient([(2, 0)], [0.5], [0.0], eps)  # type: ignore[arg-type]


def test_invalid_points_and_modes_raise() -> None:
    with pytest.raises(ValueError, match="same length"):
        annular_zernike_basis([(2, 0)], [0.5, 0.6], [0.0], 0.3)
    with pytest.raises(ValueError, match="even"):
        annular_zernike_gradient([(3, 0)], [0.5], [0.0], 0.3)
    with pytest.raises(ValueError, match="finite"):
        annular_radial(2, 0, [np.nan], 0.3)
