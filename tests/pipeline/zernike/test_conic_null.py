"""The conic null at the centre of curvature against its fourth-order limit and known cases."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.zernike.conic_null import (
    ConicTest,
    implied_conic_constant,
    null_spherical_coefficients,
    null_wavefront_waves,
)

MIRROR = ConicTest(radius_of_curvature_mm=1215.0, diameter_mm=152.2, wavelength_nm=654.0)


def test_a_sphere_needs_no_null() -> None:
    rho = np.linspace(0, 1, 101)
    np.testing.assert_allclose(null_wavefront_waves(rho, MIRROR, 0.0), 0.0, atol=1e-9)


def test_slow_mirror_matches_the_fourth_order_formula() -> None:
    slow = ConicTest(radius_of_curvature_mm=4000.0, diameter_mm=100.0, wavelength_nm=632.8)  # f/20
    h = np.linspace(0, 50.0, 51)
    fourth_order = 1.0 * h**4 / (4 * 4000.0**3) * 1e6 / 632.8  # K = -1: -K h^4 / (4 R^3)
    exact = null_wavefront_waves(h / 50.0, slow, -1.0)
    # higher orders scale as (h/R)^2 ~ 1.6e-4 relative at f/20
    np.testing.assert_allclose(exact, fourth_order, rtol=2e-3, atol=1e-9)


def test_primary_spherical_of_a_paraboloid_at_f4() -> None:
    coefficients = null_spherical_coefficients(MIRROR, -1.0)
    # fourth order alone: W = a rho^4 with a = (D/2)^4 / (4 R^3) / lambda, and rho^4 carries
    # a / (6 sqrt 5) of unit-RMS Z11; higher orders add (h/R)^2 ~ 0.4 % at this f/4 mirror
    a = 76.1**4 / (4 * 1215.0**3) * 1e6 / 654.0
    assert coefficients[11] == pytest.approx(a / (6 * np.sqrt(5)), rel=0.01)
    assert abs(coefficients[22]) < 0.01 * abs(coefficients[11])  # secondary spherical is small


def test_implied_conic_constant_inverts_the_null() -> None:
    for conic in (-1.0, -0.6, 0.0, 0.4):
        spherical = null_spherical_coefficients(MIRROR, conic)[11]
        assert implied_conic_constant(spherical, MIRROR) == pytest.approx(conic, abs=1e-8)
    with pytest.raises(ValueError, match="outside the range"):
        implied_conic_constant(1e3, MIRROR)


def test_invalid_geometry_is_refused() -> None:
    with pytest.raises(ValueError, match="radius_of_curvature_mm"):
        ConicTest(-1.0, 100.0, 633.0)
    with pytest.raises(ValueError, match="diameter_mm"):
        ConicTest(100.0, 250.0, 633.0)
