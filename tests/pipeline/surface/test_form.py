"""ISO 14999-4 form figures, exact on synthetic surfaces on a circle, an annulus and odd apertures.

Each surface is a known sphere, a known rotationally symmetric term, a known asymmetric term,
plus piston and tilt. The expected figures are derived here, independently of the code under
test: the least-squares piston and tilt, and the least-squares sphere, by ``numpy.linalg.lstsq``
on the pixels; the irregularity is then split by construction into the part that depends on
the radius only (the sphere and the symmetric term, less the fitted piston and power) and the
rest (the asymmetric term less the fitted tilt), so the rotationally symmetric part is known
exactly even where the rings are incomplete.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.surface import FormAnalyzer, measured_area

SIZE = 161
CENTRE = (SIZE - 1) / 2  # every aperture here is symmetric about the grid centre


def _coordinates() -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.indices((SIZE, SIZE), dtype=np.float64)
    return cols - CENTRE, CENTRE - rows


def _circle() -> np.ndarray:
    x, y = _coordinates()
    return np.hypot(x, y) <= 76


def _annulus() -> np.ndarray:
    x, y = _coordinates()
    return (np.hypot(x, y) <= 76) & (np.hypot(x, y) >= 30)


def _off_centre_hole() -> np.ndarray:
    """A disk with a hole off the axis: most rings are incomplete."""
    x, y = _coordinates()
    return (np.hypot(x, y) <= 76) & (np.hypot(x - 28, y - 10) > 22)


def _rounded_rectangle() -> np.ndarray:
    x, y = _coordinates()
    dx, dy = np.abs(x) - (78 - 12), np.abs(y) - (30 - 12)
    return np.hypot(np.maximum(dx, 0), np.maximum(dy, 0)) <= 12


APERTURES = {"circle": _circle, "annulus": _annulus, "off-centre hole": _off_centre_hole,
             "rounded rectangle": _rounded_rectangle}


def _expected(mask: np.ndarray, sphere: float, symmetric: float, asymmetric: float) -> tuple[np.ndarray, dict]:
    """The surface (nm) and its figures, derived by least squares and by construction."""
    x_px, y_px = _coordinates()
    x_px, y_px = x_px[mask], y_px[mask]
    radius = float(np.max(np.hypot(x_px, y_px)))  # the enclosing circle of a centred symmetric set
    x, y = x_px / radius, y_px / radius
    u = x * x + y * y
    radial = sphere * u + symmetric * (20 * u**3 - 30 * u**2 + 12 * u - 1)  # sphere + Z(6,0)
    angular = asymmetric * ((x**3 - 3 * x * y**2) + 0.7 * (3 * u - 2) * y)  # trefoil and coma (order 3)
    values = 12.0 + 40.0 * x - 25.0 * y + radial + angular  # piston and tilt: positioning
    ptt, *_ = np.linalg.lstsq(np.column_stack([np.ones_like(x), x, y]), values, rcond=None)
    sphere_fit, *_ = np.linalg.lstsq(np.column_stack([np.ones_like(x), x, y, u]), values, rcond=None)
    deviation = values - ptt[0] - ptt[1] * x - ptt[2] * y
    symmetric_part = 12.0 + radial - sphere_fit[0] - sphere_fit[3] * u  # the piston is radial too
    asymmetric_part = 40.0 * x - 25.0 * y + angular - sphere_fit[1] * x - sphere_fit[2] * y
    irregularity = symmetric_part + asymmetric_part
    assert np.allclose(irregularity, values - np.column_stack([np.ones_like(x), x, y, u]) @ sphere_fit)
    surface = np.full(mask.shape, np.nan)
    surface[mask] = values
    return surface, {
        "sag_nm": sphere_fit[3], "irr_nm": np.ptp(irregularity), "rsi_nm": np.ptp(symmetric_part),
        "rmst_nm": np.std(deviation), "rmsi_nm": np.std(irregularity), "rmsa_nm": np.std(asymmetric_part),
        "pv_nm": np.ptp(deviation),
    }


@pytest.mark.parametrize("aperture", APERTURES)
def test_form_figures_are_exact_on_a_sphere_a_symmetric_and_an_asymmetric_term(aperture: str) -> None:
    mask = APERTURES[aperture]()
    surface, expected = _expected(mask, sphere=150.0, symmetric=18.0, asymmetric=25.0)
    figures = FormAnalyzer(measured_area(mask)).figures(surface)
    for name, value in expected.items():
        # exact up to the rounding of the least-squares solves (the figures are 10-300 nm; the
        # radial model's normal equations lose about half the digits: 1e-6 nm is 1e-8 of them);
        # SAG also scales with the enclosing circle's radius squared, which the aperture enlarges
        # by a relative 1e-9 so that every pixel centre lies inside it
        assert getattr(figures, name) == pytest.approx(value, rel=3e-9, abs=1e-6), name


@pytest.mark.parametrize("aperture", APERTURES)
def test_the_sphere_alone_is_all_sag_and_no_irregularity(aperture: str) -> None:
    mask = APERTURES[aperture]()
    surface, expected = _expected(mask, sphere=-80.0, symmetric=0.0, asymmetric=0.0)
    figures = FormAnalyzer(measured_area(mask)).figures(surface)
    assert figures.sag_nm == pytest.approx(-80.0, rel=3e-9)  # signed: the edge falls
    assert figures.irr_nm < 1e-8 and figures.rsi_nm < 1e-8 and figures.rmsa_nm < 1e-8
    assert figures.rmst_nm == pytest.approx(expected["rmst_nm"], abs=1e-8)


def test_an_asymmetric_term_alone_has_no_rotationally_symmetric_part_even_on_incomplete_rings() -> None:
    mask = _off_centre_hole()
    surface, expected = _expected(mask, sphere=0.0, symmetric=0.0, asymmetric=30.0)
    figures = FormAnalyzer(measured_area(mask)).figures(surface)
    # the fitted sphere takes some power from the asymmetric term here (the hole breaks the
    # symmetry), and that power's removal is rotationally symmetric; nothing else is
    assert figures.rsi_nm == pytest.approx(expected["rsi_nm"], abs=1e-6)
    # without the asymmetric terms of order 3 and 5 in the joint fit, the incomplete rings lend
    # their asymmetric content to the radial profile: the check above would fail
    blind = FormAnalyzer(measured_area(mask), asymmetric_order=1).figures(surface)
    assert abs(blind.rsi_nm - expected["rsi_nm"]) > 0.1


def test_a_rotationally_symmetric_ripple_is_caught_by_rsi() -> None:
    """A turned part's zone: a ripple in radius that no low-order Zernike term holds."""
    mask = _circle()
    x, y = _coordinates()
    rho = np.hypot(x, y) / 76
    ripple = 10.0 * np.exp(-((rho - 0.7) / 0.06) ** 2)
    figures = FormAnalyzer(measured_area(mask)).figures(np.where(mask, ripple, np.nan))
    # the zone is the whole irregularity (bar its share of the sphere): RSI ~ IRR, RMSa ~ 0
    assert figures.rsi_nm == pytest.approx(figures.irr_nm, rel=0.02)
    assert figures.rmsa_nm < 0.02 * figures.rmsi_nm


def test_refuses_a_map_with_a_missing_measured_pixel_and_a_map_of_another_shape() -> None:
    mask = _circle()
    analyzer = FormAnalyzer(measured_area(mask))
    surface = np.where(mask, 1.0, np.nan)
    surface[80, 80] = np.nan
    with pytest.raises(ValueError, match="1 measured pixels are NaN"):
        analyzer.figures(surface)
    with pytest.raises(ValueError, match=r"expected a map of shape \(161, 161\)"):
        analyzer.figures(np.zeros((10, 10)))


def test_refuses_an_area_too_small_for_the_model() -> None:
    mask = np.zeros((20, 20), bool)
    mask[5:12, 5:12] = True
    with pytest.raises(ValueError, match="49 measured pixels cannot determine the form figures"):
        FormAnalyzer(measured_area(mask))


def test_the_asymmetric_order_falls_where_the_rings_are_short_and_keeps_rsi_stable_in_noise() -> None:
    """On a 2.6:1 rounded rectangle terms of order 6 look radial on the short arcs: the model
    takes the order at which the split stays well conditioned, and 2 nm of white noise then moves
    RSI by about the noise (with every term to order 6 it moves it by tens of nm, past the
    irregularity itself)."""
    mask = _rounded_rectangle()
    surface, expected = _expected(mask, sphere=150.0, symmetric=18.0, asymmetric=25.0)
    analyzer = FormAnalyzer(measured_area(mask))
    assert analyzer.asymmetric_order == 3
    assert FormAnalyzer(measured_area(_off_centre_hole())).asymmetric_order == 6
    noisy = surface + np.random.default_rng(1).normal(0.0, 2.0, surface.shape)
    # the PV of 2 nm white noise over ~12000 pixels is about 16 nm; its radial mean, about 1 nm
    assert abs(analyzer.figures(noisy).rsi_nm - expected["rsi_nm"]) < 4.0
    unconstrained = FormAnalyzer(measured_area(mask), asymmetric_order=6, max_condition=1e12)
    wild = unconstrained.figures(noisy)
    assert abs(wild.rsi_nm - expected["rsi_nm"]) > 20.0 and wild.rsi_nm > wild.irr_nm


def test_a_long_thin_strip_keeps_only_tilt_beside_the_radial_profile() -> None:
    rows, cols = np.indices((33, 259))
    strip = ((rows - 16) / 16.5) ** 2 + ((cols - 129) / 129.5) ** 2 <= 1
    analyzer = FormAnalyzer(measured_area(strip))
    assert analyzer.asymmetric_order == 1
    x, y = (cols - 129) / 129.5, (16 - rows) / 129.5
    noisy = 60 * x**2 + 8 * x * y + np.random.default_rng(3).normal(0, 2, x.shape)
    figures = analyzer.figures(np.where(strip, noisy, np.nan))
    assert figures.rsi_nm <= figures.irr_nm + 1e-9  # a part of the irregularity, never more
