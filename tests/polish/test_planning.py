"""A planned job is always one the machine can execute: over random surfaces, dwell >= 0, feed and travel within limits.

The plan goes through the solver, the machine program and the gentler-solution ladder; whatever
it returns must pass the machine's own rules, and the prediction must be the program's.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import ndimage

from fuzz import fuzz_settings
from wavestack.config.polishing import MachineSettings, PolishingSettings, TifSettings
from wavestack.pipeline.polishing import GridFrame, ToolInfluence, removal_nm
from wavestack.polish.measurement import average_surface
from wavestack.station import MapSample
from wavestack.polish.planning import GENTLER, NoFittingJob, lattice_points, plan_job

SHAPE, PIXEL_MM = (32, 32), 0.5
TIF = TifSettings(fwhm_mm=2.0, peak_rate_nm_s=5.0)


def _measurement(seed: int, amplitude_nm: float, correlation_px: float):
    rng = np.random.default_rng(seed)
    rows, cols = np.indices(SHAPE) - 15.5
    mask = np.hypot(rows, cols) <= 9.0
    field = ndimage.gaussian_filter(rng.normal(size=SHAPE), correlation_px)
    field = amplitude_nm * field / field[mask].std() + amplitude_nm * rng.normal() * (rows**2 - cols**2) / 81.0
    waves = np.where(mask, field * 2.0 / 600.0, np.nan)  # nm of surface -> waves of wavefront
    return average_surface([MapSample(waves, True, None, 0, 0)] * 2, wavelength_nm=600.0, reflection_factor=2.0,
                           min_count=2)


@fuzz_settings(200)
@given(st.integers(0, 2**32 - 1), st.floats(1.0, 200.0), st.floats(1.0, 6.0), st.integers(1, 3),
       st.sampled_from(["raster", "spiral"]), st.floats(5.0, 200.0), st.sampled_from(["fft", "bounded"]))
def test_a_planned_job_is_executable(seed: int, amplitude_nm: float, correlation_px: float, step_px: int,
                                     path: str, max_feed_mm_s: float, solver: str) -> None:
    measurement = _measurement(seed, amplitude_nm, correlation_px)
    machine = MachineSettings(max_feed_mm_s=max_feed_mm_s, max_accel_mm_s2=500.0, travel_x_mm=(-9.0, 9.0),
                              travel_y_mm=(-9.0, 9.0), max_dwell_per_point_s=30.0, path=path, step_px=step_px)
    settings = PolishingSettings(pixel_mm=PIXEL_MM, tif=TIF, machine=machine, max_total_dwell_s=5000.0,
                                 max_removal_nm_per_run=2000.0, solver=solver)
    tif = ToolInfluence.gaussian(TIF.fwhm_mm, TIF.peak_rate_nm_s, PIXEL_MM)
    try:
        job = plan_job(measurement, tif, settings)
    except NoFittingJob:
        return  # refused with its reasons: nothing is sent
    program = job.program
    assert np.all(program.dwell_s >= 0) and np.all(job.dwell_s >= 0)
    assert np.all(program.feed_mm_s > 0) and np.all(program.feed_mm_s <= max_feed_mm_s * (1 + 1e-9))
    assert np.all((program.x_mm >= -9.0) & (program.x_mm <= 9.0))
    assert np.all((program.y_mm >= -9.0) & (program.y_mm <= 9.0))
    assert program.dwell_s.max() <= 30.0 * (1 + 1e-9) and program.total_dwell_s <= 5000.0 * (1 + 1e-9)
    # the prediction is the program's own: its dwell map, convolved with the host's TIF
    np.testing.assert_allclose(job.dwell_s, program.dwell_map(GridFrame(SHAPE, PIXEL_MM)), atol=1e-9)
    np.testing.assert_allclose(job.removal_nm, removal_nm(job.dwell_s, tif), atol=1e-6)
    assert job.removal_nm.max() <= 2000.0 and np.isfinite(job.predicted_rms_nm)
    assert job.solution.solver == solver
    assert job.floor is not None and job.floor.floor_nm >= job.predicted_rms_nm


def test_the_ladder_refuses_with_every_reason_when_nothing_fits() -> None:
    measurement = _measurement(1, 100.0, 3.0)
    settings = PolishingSettings(pixel_mm=PIXEL_MM, tif=TIF, max_total_dwell_s=0.5,
                                 machine=MachineSettings(travel_x_mm=(-9.0, 9.0), travel_y_mm=(-9.0, 9.0)))
    tif = ToolInfluence.gaussian(TIF.fwhm_mm, TIF.peak_rate_nm_s, PIXEL_MM)
    with pytest.raises(NoFittingJob, match=r"no fft job fits the limits \(10 tried\)"):  # 5 rungs, then clipped
        plan_job(measurement, tif, settings)


def test_lattice_points_are_centred_and_inside() -> None:
    points = lattice_points((9, 12), 4)
    assert points.min() >= 0 and points[:, 0].max() < 9 and points[:, 1].max() < 12
    assert (4, 5) in {tuple(int(v) for v in p) for p in points}  # the grid's centre pixel is a point
    assert len(points) == 3 * 3 and np.all(np.diff(np.unique(points[:, 1])) == 4)


def test_the_least_squares_plan_is_executable_and_improves() -> None:
    measurement = _measurement(4, 50.0, 4.0)
    machine = MachineSettings(travel_x_mm=(-9.0, 9.0), travel_y_mm=(-9.0, 9.0), max_dwell_per_point_s=30.0, step_px=2)
    settings = PolishingSettings(pixel_mm=PIXEL_MM, tif=TIF, machine=machine, solver="lsq")
    tif = ToolInfluence.gaussian(TIF.fwhm_mm, TIF.peak_rate_nm_s, PIXEL_MM)
    job = plan_job(measurement, tif, settings)
    assert job.solution.solver == "lsq" and np.all(job.program.dwell_s <= 30.0 * (1 + 1e-9))
    # a bounded least-squares dwell on a 1 mm lattice with a 2 mm tool: at least half the error goes
    assert job.predicted_rms_nm < 0.5 * measurement.rms_nm


def test_a_solution_over_the_per_point_limit_is_clipped_only_when_nothing_fits_and_only_if_it_helps() -> None:
    measurement = _measurement(3, 50.0, 3.0)
    tif = ToolInfluence.gaussian(TIF.fwhm_mm, TIF.peak_rate_nm_s, PIXEL_MM)

    def settings(max_dwell_per_point_s: float) -> PolishingSettings:
        machine = MachineSettings(travel_x_mm=(-9.0, 9.0), travel_y_mm=(-9.0, 9.0),
                                  max_dwell_per_point_s=max_dwell_per_point_s, step_px=1)
        return PolishingSettings(pixel_mm=PIXEL_MM, tif=TIF, machine=machine, max_total_dwell_s=1e5,
                                 max_removal_nm_per_run=5000.0)

    # a generous limit: a gentler rung fits as it is, and it is taken unclipped (far better than a clipped one)
    roomy = plan_job(measurement, tif, settings(60.0))
    assert roomy.predicted_rms_nm < 0.1 * measurement.rms_nm
    # a limit no rung meets as it is (each asks more at some point): a clipped job, within the limit, that helps
    tight = plan_job(measurement, tif, settings(8.0))
    assert tight.program.dwell_s.max() <= 8.0 * (1 + 1e-9)
    assert tight.predicted_rms_nm < 0.75 * measurement.rms_nm


def test_the_bounded_plan_fits_the_limits_at_its_first_rung_and_improves() -> None:
    measurement = _measurement(4, 50.0, 2.0)
    machine = MachineSettings(travel_x_mm=(-9.0, 9.0), travel_y_mm=(-9.0, 9.0), max_dwell_per_point_s=4.0, step_px=1)
    settings = PolishingSettings(pixel_mm=PIXEL_MM, tif=TIF, machine=machine, solver="bounded",
                                 max_total_dwell_s=400.0, max_removal_nm_per_run=500.0)
    tif = ToolInfluence.gaussian(TIF.fwhm_mm, TIF.peak_rate_nm_s, PIXEL_MM)
    job = plan_job(measurement, tif, settings)
    assert job.solution.solver == "bounded" and job.gentleness == GENTLER["bounded"][0]
    assert job.program.dwell_s.max() <= 4.0 * (1 + 1e-9) and job.program.total_dwell_s <= 400.0 * (1 + 1e-9)
    assert job.removal_nm.max() <= 500.0
    assert job.predicted_rms_nm < 0.5 * measurement.rms_nm
