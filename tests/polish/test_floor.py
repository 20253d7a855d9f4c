"""The floor of a job: its terms, how they scale, and that they add in quadrature."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from wavestack.pipeline.polishing import ToolInfluence, dwell_grid, removal_nm
from wavestack.polish.floor import JobFloor, job_floor

TIF = ToolInfluence.gaussian(fwhm_mm=2.0, peak_rate_nm_s=5.0, pixel_mm=0.5)


def _job(seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.indices((48, 48)) - 23.5
    mask = np.hypot(rows, cols) <= 14.0
    rng = np.random.default_rng(seed)
    dwell = np.where(dwell_grid(mask, TIF), 1.0 + ndimage.gaussian_filter(rng.random((48, 48)), 2.0), 0.0)
    return dwell, mask


def _floor(dwell: np.ndarray, mask: np.ndarray, **overrides: float) -> JobFloor:
    terms = dict(rate_uncertainty=0.03, width_uncertainty=0.03, efficiency_spread=0.02, process_noise_nm=0.2,
                 measurement_noise_nm=0.1)
    points = np.argwhere(dwell > 0)  # every pixel a program point
    return job_floor(dwell, 2.0, mask, TIF, points_px=points.astype(float), points_dwell_s=dwell[dwell > 0],
                     **{**terms, **overrides})


def test_the_terms_add_in_quadrature() -> None:
    dwell, mask = _job()
    floor = _floor(dwell, mask)
    total = math.sqrt(2.0**2 + floor.model_nm**2 + floor.efficiency_nm**2 + 0.2**2 + 2 * 0.1**2)
    assert floor.floor_nm == pytest.approx(total)
    assert floor.reach_nm == 2.0 and floor.model_nm > 0 and floor.efficiency_nm > 0
    assert "floor" in floor.describe()


def test_with_no_errors_the_floor_is_the_reach() -> None:
    dwell, mask = _job()
    floor = _floor(dwell, mask, rate_uncertainty=0.0, width_uncertainty=0.0, efficiency_spread=0.0,
                   process_noise_nm=0.0, measurement_noise_nm=0.0)
    assert floor.model_nm == pytest.approx(0.0, abs=1e-9) and floor.floor_nm == pytest.approx(2.0)


def test_the_machine_terms_scale_with_the_removal_and_the_errors() -> None:
    dwell, mask = _job(3)
    once, twice = _floor(dwell, mask), _floor(2.0 * dwell, mask)
    assert twice.model_nm == pytest.approx(2.0 * once.model_nm, rel=1e-6)  # linear in the dwell
    assert twice.efficiency_nm == pytest.approx(2.0 * once.efficiency_nm, rel=1e-6)
    wider = _floor(dwell, mask, efficiency_spread=0.04)
    assert wider.efficiency_nm == pytest.approx(2.0 * once.efficiency_nm, rel=1e-6)
    assert _floor(dwell, mask, rate_uncertainty=0.06).model_nm > once.model_nm


@pytest.mark.parametrize("step", [1, 3])
def test_the_efficiency_term_matches_a_random_draw_per_point(step: int) -> None:
    # s^2/3 * (d_k^2 * K^2): the variance of sum_k e_k d_k K(x - x_k) with e_k uniform on +-s,
    # one e_k per program point (a point every `step` pixels gathers the dwell around it)
    dwell, mask = _job(5)
    points = np.argwhere(dwell > 0)
    points = points[(points[:, 0] % step == 0) & (points[:, 1] % step == 0)]
    point_dwell = dwell[points[:, 0], points[:, 1]] * step**2
    at = np.zeros(dwell.shape)
    at[points[:, 0], points[:, 1]] = point_dwell
    floor = job_floor(at, 2.0, mask, TIF, points_px=points.astype(float), points_dwell_s=point_dwell,
                      rate_uncertainty=0.0, width_uncertainty=0.0, efficiency_spread=0.1, process_noise_nm=0.0,
                      measurement_noise_nm=0.0)
    rng = np.random.default_rng(0)
    draws = [removal_nm(at * rng.uniform(-0.1, 0.1, at.shape), TIF)[mask] for _ in range(300)]
    assert float(np.sqrt(np.mean(np.var(draws, axis=0)))) == pytest.approx(floor.efficiency_nm, rel=0.1)
