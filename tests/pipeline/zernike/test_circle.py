"""Tests for the circle Zernike polynomials and their Cartesian derivatives."""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np
import pytest

from wavestack.pipeline.zernike.circle import zernike_basis, zernike_gradient, zernike_radial
from wavestack.pipeline.zernike.indices import mode_list, noll_to_nm
from wavestack.pipeline.zernike.normalisation import normalisation_factor

N_MAX = 20
ALL_MODES = [(n, m) for n in range(N_MAX + 1) for m in range(-n, n + 1, 2)]
# Rational radii, including the centre, the edge and one point outside the disk.
RADII = [Fraction(0), Fraction(1, 7), Fraction(1, 3), Fraction(1, 2), Fraction(5, 7),
         Fraction(9, 10), Fraction(1), Fraction(6, 5)]  # fmt: skip


def exact_coefficients(n: int, m: int) -> list[tuple[int, Fraction]]:
    """Terms (power, coefficient) of R_n^m from the factorial sum (Noll 1976), exactly."""
    m = abs(m)
    return [
        (
            n - 2 * s,
            Fraction(
                (-1) ** s * factorial(n - s),
                factorial(s) * factorial((n + m) // 2 - s) * factorial((n - m) // 2 - s),
            ),
        )
        for s in range((n - m) // 2 + 1)
    ]


def exact_radial(n: int, m: int, r: Fraction) -> Fraction:
    return sum((c * r**p for p, c in exact_coefficients(n, m)), Fraction(0))


def exact_slope(n: int, m: int, r: Fraction) -> Fraction:
    return sum((c * p * r ** (p - 1) for p, c in exact_coefficients(n, m) if p > 0), Fraction(0))


def exact_over_r(n: int, m: int, r: Fraction) -> Fraction:
    """R / r as the polynomial it is (every power is >= |m| >= 1)."""
    return sum((c * r ** (p - 1) for p, c in exact_coefficients(n, m)), Fraction(0))


def four_point_derivative(
    function: object, x: np.ndarray, y: np.ndarray, step: float
) -> tuple[np.ndarray, np.ndarray]:
    """Fourth-order central differences of function(x, y) -> (N, M) along x and y."""
    f = function  # type: ignore[assignment]

    def along(dx: float, dy: float) -> np.ndarray:
        return (
            -f(x + 2 * dx, y + 2 * dy) + 8 * f(x + dx, y + dy)
            - 8 * f(x - dx, y - dy) + f(x - 2 * dx, y - 2 * dy)
        ) / (12 * step)  # fmt: skip

    return along(step, 0.0), along(0.0, step)


# --------------------------------------------------------------------------- radial values


def test_radial_matches_exact_factorial_sum() -> None:
    radii = np.array([float(r) for r in RADII])
    for n in range(N_MAX + 1):
        for m in range(n % 2, n + 1, 2):
            expected = np.array([float(exact_radial(n, m, r)) for r in RADII])
            got = zernike_radial(n, m, radii)
            # The recurrence adds O(1) rounding errors of size ~1e-16 per step over n <= 20
            # steps and |R| <= 1 on the disk; measured worst case 1e-15.  Outside the disk
            # R grows like rho^n, so the bound is relative to max(1, |R|).  1e-12 leaves
            # wide margin yet fails for the float factorial sum at n = 20 (~2e-10 error).
            np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12, err_msg=f"{n, m}")


def test_radial_low_orders_and_sign_of_m() -> None:
    rho = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(zernike_radial(2, 0, rho), 2 * rho**2 - 1, atol=1e-15)
    np.testing.assert_allclose(zernike_radial(3, 1, rho), 3 * rho**3 - 2 * rho, atol=1e-15)
    np.testing.assert_allclose(
        zernike_radial(4, 0, rho), 6 * rho**4 - 6 * rho**2 + 1, atol=1e-15
    )
    np.testing.assert_array_equal(zernike_radial(5, -3, rho), zernike_radial(5, 3, rho))
    assert zernike_radial(20, 0, 1.0) == pytest.approx(1.0, abs=1e-14)
    assert np.shape(zernike_radial(2, 2, 0.5)) == ()


def test_radial_derivative_and_quotient_on_axes_match_exact() -> None:
    # On the +x axis (theta = 0) the edge-normalised gradient reduces to the radial parts:
    # cosine terms give dZ/dx = R'(r); sine terms give dZ/dy = |m| R(r)/r.
    radii = [r for r in RADII if r > 0]
    x = np.array([float(r) for r in radii])
    y = np.zeros_like(x)
    cos_modes = [(n, m) for n, m in ALL_MODES if m >= 0]
    sin_modes = [(n, m) for n, m in ALL_MODES if m < 0]
    dx_cos, _ = zernike_gradient(cos_modes, x, y, normalisation="edge")
    _, dy_sin = zernike_gradient(sin_modes, x, y, normalisation="edge")
    for column, (n, m) in enumerate(cos_modes):
        expected = np.array([float(exact_slope(n, m, r)) for r in radii])
        # |R'| <= n^2 = 400 on the disk; relative 1e-12 is ~1e4 ulp of that scale
        # (measured relative error 1.3e-14).
        np.testing.assert_allclose(dx_cos[:, column], expected, rtol=1e-12, atol=1e-12 * n**2)
    for column, (n, m) in enumerate(sin_modes):
        expected = np.array([float(-m * exact_over_r(n, m, r)) for r in radii])
        np.testing.assert_allclose(dy_sin[:, column], expected, rtol=1e-12, atol=1e-12 * n**2)


# --------------------------------------------------------------------------- orthonormality


def test_orthonormal_over_unit_disk_up_to_n20() -> None:
    # Gauss-Legendre in rho with 22 nodes integrates polynomials of degree <= 43 exactly;
    # R_i R_j rho has degree <= 2*20 + 1 = 41.  The trapezoid rule with P points in theta
    # is exact for trigonometric polynomials of frequency < P; products reach 2*20 = 40,
    # so P = 48 > 2*m_max + 1 is exact.  The remaining error is rounding only.
    nodes, weights = np.polynomial.legendre.leggauss(22)
    rho = 0.5 * (nodes + 1.0)
    radial_weight = 0.5 * weights * rho
    angles = 2.0 * np.pi * np.arange(48) / 48
    r_grid, t_grid = np.meshgrid(rho, angles, indexing="ij")
    w = (radial_weight[:, None] * np.full(48, 2.0 * np.pi / 48)).ravel()
    x, y = (r_grid * np.cos(t_grid)).ravel(), (r_grid * np.sin(t_grid)).ravel()
    basis = zernike_basis(ALL_MODES, x, y)
    gram = basis.T @ (w[:, None] * basis) / np.pi  # mean over the disk of area pi
    assert len(ALL_MODES) == 231
    # Measured ~3e-14 (sums of 1056 products of O(1..20) values); 1e-10 is the spec.
    np.testing.assert_allclose(gram, np.eye(len(ALL_MODES)), rtol=0, atol=1e-10)


def test_noll_basis_known_terms() -> None:
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-0.7, 0.7, (2, 25))
    rho2, theta = x**2 + y**2, np.arctan2(y, x)
    basis = zernike_basis(mode_list("noll", 6), x, y)
    expected = np.stack(
        [
            np.ones_like(x),
            2 * x,
            2 * y,
            np.sqrt(3) * (2 * rho2 - 1),
            np.sqrt(6) * rho2 * np.sin(2 * theta),
            np.sqrt(6) * rho2 * np.cos(2 * theta),
        ],
        axis=1,
    )
    np.testing.assert_allclose(basis, expected, rtol=1e-13, atol=1e-14)


def test_edge_normalisation_is_one_at_the_edge() -> None:
    modes = [(n, m) for n, m in ALL_MODES if m >= 0]
    values = zernike_basis(modes, [1.0], [0.0], normalisation="edge")
    # R_n^m(1) = 1 exactly in exact arithmetic; the recurrence sums O(n) terms of size 1.
    np.testing.assert_allclose(values[0], 1.0, rtol=0, atol=1e-13)
    rms = zernike_basis(modes, [1.0], [0.0], normalisation="rms")
    factors = [normalisation_factor(n, m, "rms") for n, m in modes]
    np.testing.assert_allclose(rms[0], factors, rtol=1e-13)


def test_points_outside_the_disk_are_polynomial_values() -> None:
    basis = zernike_basis([(4, 0)], [1.5], [0.0], normalisation="edge")
    assert basis[0, 0] == pytest.approx(6 * 1.5**4 - 6 * 1.5**2 + 1, rel=1e-14)


# --------------------------------------------------------------------------- gradient


def test_gradient_matches_finite_differences() -> None:
    modes = [(n, m) for n, m in ALL_MODES if n <= 12]
    rng = np.random.default_rng(11)
    x, y = rng.uniform(-0.7, 0.7, (2, 40))
    x[0], y[0] = 0.0, 0.0  # the origin
    x[1], y[1] = 0.3, 0.0  # on an axis
    dzdx, dzdy = zernike_gradient(modes, x, y)
    fd_x, fd_y = four_point_derivative(lambda u, v: zernike_basis(modes, u, v), x, y, 1e-4)
    # Fourth-order differences with h = 1e-4: truncation h^4 |f^(5)| / 30 and rounding
    # ~ u |f| / h, both below ~1e-9 for n <= 12 (measured 7e-11 on gradients up to ~30).
    tolerance = 1e-8 * (1.0 + np.abs(dzdx).max())
    np.testing.assert_allclose(dzdx, fd_x, rtol=0, atol=tolerance)
    np.testing.assert_allclose(dzdy, fd_y, rtol=0, atol=tolerance)


@pytest.mark.parametrize("origin", [(0.0, 0.0), (-0.0, -0.0), (0.0, -0.0)])
def test_gradient_exact_at_origin(origin: tuple[float, float]) -> None:
    # Near 0 only m = +-1 terms are linear: R_n^1(r) = c_n r + O(r^3) with c_n the
    # coefficient of r^1, so Z = N c_n x (cos) or N c_n y (sin); all others have zero
    # gradient.  Signed zeros give arctan2 = 0 or -pi; the result must not depend on it.
    dzdx, dzdy = zernike_gradient(ALL_MODES, [origin[0]], [origin[1]])
    for column, (n, m) in enumerate(ALL_MODES):
        linear = float(exact_slope(n, 1, Fraction(0))) if abs(m) == 1 else 0.0
        factor = normalisation_factor(n, m, "rms")
        expected_x = factor * linear if m == 1 else 0.0
        expected_y = factor * linear if m == -1 else 0.0
        # |N c_n| <= sqrt(42) * 11; the recurrence gives these exactly up to rounding.
        assert dzdx[0, column] == pytest.approx(expected_x, abs=1e-12), (n, m)
        assert dzdy[0, column] == pytest.approx(expected_y, abs=1e-12), (n, m)


def test_physical_orientation() -> None:
    tilt_x, tilt_y = noll_to_nm(2), noll_to_nm(3)
    x = np.array([-0.5, 0.0, 0.5, 0.0, 0.0])
    y = np.array([0.0, 0.0, 0.0, -0.5, 0.5])
    values = zernike_basis([tilt_x, tilt_y], x, y)
    assert values[0, 0] < values[1, 0] < values[2, 0]  # Noll 2 increases with x
    assert values[3, 1] < values[1, 1] < values[4, 1]  # Noll 3 increases with y
    dzdx, dzdy = zernike_gradient([tilt_x, tilt_y], x, y)
    np.testing.assert_allclose(dzdx[:, 0], 2.0, rtol=1e-15)  # Z2 = 2x
    np.testing.assert_allclose(dzdy[:, 1], 2.0, rtol=1e-15)  # Z3 = 2y
    np.testing.assert_allclose(dzdy[:, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(dzdx[:, 1], 0.0, atol=1e-15)


# --------------------------------------------------------------------------- shapes and errors


def test_shapes_and_order() -> None:
    modes = [(2, 0), (1, -1), (2, 0)]
    basis = zernike_basis(modes, [0.1, 0.2, 0.3], [0.0, 0.1, 0.2])
    assert basis.shape == (3, 3)
    np.testing.assert_array_equal(basis[:, 0], basis[:, 2])
    assert zernike_basis([], [0.1, 0.2], [0.0, 0.0]).shape == (2, 0)
    gx, gy = zernike_gradient(modes, np.zeros(0), np.zeros(0))
    assert gx.shape == gy.shape == (0, 3)


@pytest.mark.parametrize(
    ("modes", "x", "y", "message"),
    [
        ([(2, 0)], [0.1, 0.2], [0.1], "same length"),
        ([(2, 0)], [[0.1]], [[0.1]], "1-D"),
        ([(2, 0)], [np.nan], [0.0], "finite"),
        ([(2, 1)], [0.1], [0.1], "even"),
        ([(2,)], [0.1], [0.1], "pair"),
        ([3], [0.1], [0.1], "pair"),
    ],
)
@pytest.mark.parametrize("function", [zernike_basis, zernike_gradient])
def test_bad_input_raises(
    function: object, modes: object, x: object, y: object, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        function(modes, x, y)  # type: ignore[operator]


def test_bad_normalisation_and_radial_input_raise() -> None:
    with pytest.raises(ValueError, match="normalisation"):
        zernike_basis([(1, 1)], [0.1], [0.1], normalisation="peak")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="even"):
        zernike_radial(3, 0, [0.5])
    with pytest.raises(ValueError, match="finite"):
        zernike_radial(2, 0, [np.inf])
