"""Tests for wavestack.pipeline.polishing.lsq_solver: bounded least squares on any dwell points."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.ndimage import gaussian_filter

from fuzz import fuzz_settings
from wavestack.pipeline.polishing import ToolInfluence, dwell_grid, removal_nm, solve_dwell_lsq

TIF = ToolInfluence.gaussian(fwhm_mm=1.5, peak_rate_nm_s=2.0, pixel_mm=0.25)  # FWHM 6 px, radius 7 px


def _disc(shape: tuple[int, int], radius: float) -> np.ndarray:
    rows, cols = np.indices(shape) - (np.array(shape)[:, None, None] - 1) / 2
    return rows**2 + cols**2 < radius**2


def _lattice(grid: np.ndarray, step: int) -> np.ndarray:
    rows, cols = np.nonzero(grid)
    keep = (rows % step == 0) & (cols % step == 0)
    return np.c_[rows[keep], cols[keep]]


def _smooth_surface(shape: tuple[int, int], radius: float, seed: int, rms_nm: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    field = gaussian_filter(rng.normal(size=shape), 4.0)
    rows, cols = (np.indices(shape) - (np.array(shape)[:, None, None] - 1) / 2) / radius
    aperture = _disc(shape, radius)
    total = field / field[aperture].std() + rng.normal() * (rows**2 + cols**2) + rng.normal() * cols
    return np.where(aperture, total * rms_nm / total[aperture].std(), np.nan)


def test_a_surface_made_by_a_known_dwell_on_the_points_is_recovered() -> None:
    shape = (48, 48)
    aperture = _disc(shape, 14)
    points = _lattice(dwell_grid(aperture, TIF), 2)
    rng = np.random.default_rng(8)
    known = np.zeros(shape)
    smooth = 1.0 + 4.0 * gaussian_filter(rng.random(shape), 4)
    known[points[:, 0], points[:, 1]] = smooth[points[:, 0], points[:, 1]]
    surface = np.where(aperture, removal_nm(known, TIF), np.nan)
    solution = solve_dwell_lsq(surface, aperture, TIF, points_px=points)
    # An exact solution exists; the iterative solvers stop early (that is their regularisation,
    # the matrix is a Gaussian deconvolution with a condition number ~1e4), so what is left is
    # the part of the surface in the TIF's weakest singular directions: measured 2.5 % of the
    # input RMS here. 5 % is a bound with margin that a wrong matrix (a shifted or mis-scaled
    # column) cannot meet: it would leave tens of percent.
    assert solution.rms_nm < 0.05 * np.nanstd(surface)
    assert solution.diagnostics["points_used"] == points.shape[0]


@fuzz_settings(20)
@given(seed=st.integers(0, 2**31 - 1), max_dwell_s=st.floats(0.05, 5.0), step=st.sampled_from([1, 2, 3]))
def test_dwell_respects_its_bounds_and_the_grid(seed: int, max_dwell_s: float, step: int) -> None:
    shape = (36, 36)
    surface = _smooth_surface(shape, 10.0, seed, rms_nm=20.0)
    aperture = np.isfinite(surface)
    grid = dwell_grid(aperture, TIF)
    solution = solve_dwell_lsq(surface, aperture, TIF, points_px=_lattice(grid, step), max_dwell_s=max_dwell_s,
                               max_iter=20)
    assert solution.dwell_s.min() >= 0.0
    assert solution.dwell_s.max() <= max_dwell_s
    assert np.all(solution.dwell_s[~grid] == 0.0)
    lattice = np.zeros(shape, bool)
    lattice[_lattice(grid, step)[:, 0], _lattice(grid, step)[:, 1]] = True
    assert np.all(solution.dwell_s[~lattice] == 0.0)  # dwell only at the points given
    assert solution.rms_nm <= np.nanstd(surface) + 1e-9  # zero dwell is feasible: never worse


def test_a_binding_limit_costs_figure_but_is_kept() -> None:
    surface = _smooth_surface((40, 40), 12.0, seed=3, rms_nm=30.0)
    aperture = np.isfinite(surface)
    free = solve_dwell_lsq(surface, aperture, TIF)
    limit = 0.5 * float(free.dwell_s.max())
    bounded = solve_dwell_lsq(surface, aperture, TIF, max_dwell_s=limit)
    assert bounded.dwell_s.max() <= limit
    assert bounded.diagnostics["at_max_dwell"] > 0
    assert free.rms_nm < 0.25 * np.nanstd(surface)  # smooth surface, full grid: well corrected
    assert bounded.rms_nm >= free.rms_nm * 0.99  # a tighter bound cannot do (much) better


def test_points_outside_the_grid_get_no_dwell() -> None:
    shape = (40, 40)
    surface = _smooth_surface(shape, 8.0, seed=4, rms_nm=10.0)
    aperture = np.isfinite(surface)
    points = np.r_[_lattice(dwell_grid(aperture, TIF), 2), [[0, 0], [39, 1]]]
    solution = solve_dwell_lsq(surface, aperture, TIF, points_px=points)
    assert solution.diagnostics["points_outside_grid"] == 2
    assert solution.dwell_s[0, 0] == 0.0 and solution.dwell_s[39, 1] == 0.0


def test_damping_shortens_the_dwell() -> None:
    surface = _smooth_surface((40, 40), 12.0, seed=5, rms_nm=30.0)
    aperture = np.isfinite(surface)
    plain = solve_dwell_lsq(surface, aperture, TIF)
    damped = solve_dwell_lsq(surface, aperture, TIF, damping=0.3)
    assert damped.total_dwell_s < plain.total_dwell_s
    assert damped.rms_nm > plain.rms_nm  # paid for in figure


@pytest.mark.parametrize(
    ("change", "named"),
    [("shape", "clear_aperture"), ("nan", "surface_nm"), ("empty", "clear_aperture"),
     ("points_shape", "points_px"), ("points_float", "points_px"), ("points_outside", "points_px"),
     ("points_twice", "points_px"), ("max_dwell", "max_dwell_s"), ("damping", "damping")],
)
def test_bad_inputs_are_refused_by_name(change: str, named: str) -> None:
    surface, aperture = np.zeros((30, 30)), _disc((30, 30), 8)
    kwargs: dict = {}
    if change == "shape":
        aperture = _disc((31, 30), 8)
    elif change == "nan":
        surface[15, 15] = np.nan
    elif change == "empty":
        aperture = np.zeros((30, 30), bool)
    elif change == "points_shape":
        kwargs["points_px"] = np.array([1, 2, 3])
    elif change == "points_float":
        kwargs["points_px"] = np.array([[1.5, 2.0]])
    elif change == "points_outside":
        kwargs["points_px"] = np.array([[10, 10], [30, 2]])
    elif change == "points_twice":
        kwargs["points_px"] = np.array([[10, 10], [10, 10]])
    elif change == "max_dwell":
        kwargs["max_dwell_s"] = 0.0
    else:
        kwargs["damping"] = -1.0
    with pytest.raises(ValueError, match=named):
        solve_dwell_lsq(surface, aperture, TIF, **kwargs)


def test_a_too_large_matrix_is_refused_before_it_is_built() -> None:
    surface = _smooth_surface((40, 40), 12.0, seed=6, rms_nm=5.0)
    with pytest.raises(ValueError, match="max_nonzeros"):
        solve_dwell_lsq(surface, np.isfinite(surface), TIF, max_nonzeros=1000)
