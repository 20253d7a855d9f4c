"""Tests for the test optic with a surface: the phase pipeline gives the heights back, polishing shows.

Tolerances
----------
* Four-step phase shifting, noise off, 16 bits: each pixel's phase is within 2.7e-5 rad plus the
  float32 rendering's < 1e-6 rad (the derivation is in ``test_optic.py``), i.e. 1e-5 waves of
  wavefront; with ``reflection_factor = 2`` that is ``1e-5 * 632.8 / 2 = 3.2e-3`` nm of height, per
  pixel, after removing the piston (unwrapping knows the phase only up to ``2 pi k``).
* A fitted coefficient of a nearly orthonormal basis is off by at most the largest pixel error:
  1e-5 waves.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavestack.pipeline import FitSettings, InterferometerOutcome, InterferometerSettings, measure_set
from wavestack.pipeline import build_fitter, phase_from_frames, unwrap_spatial
from wavestack.pipeline import wavefront_to_surface
from wavestack.simulators import SurfaceSettings
from wavestack.simulators.optic import ApertureShape, OpticSettings, OpticTruth, TestOptic

SIZE = 256
WAVELENGTH_NM = 632.8
CIRCLE = ApertureShape(centre_px=(130.3, 124.8), radius_px=100.0)
ANNULUS = ApertureShape(kind="annulus", centre_px=(128.4, 127.9), radius_px=90.0, inner_radius_px=30.0)
STEPS = np.arange(4) * np.pi / 2
PIXEL_TOL_WAVES = 1e-5
PIXEL_TOL_NM = PIXEL_TOL_WAVES * WAVELENGTH_NM / 2.0
SURFACE = SurfaceSettings(zernike_nm=(0.0, 0.0, 0.0, 40.0, 0.0, 0.0, 0.0, 12.0), roughness_rms_nm=3.0,
                          roughness_correlation_mm=0.8, pixel_mm=0.1, seed=2, wavelength_nm=WAVELENGTH_NM)

def measured_set(frames: np.ndarray, method: str = "psi") -> InterferometerOutcome:
    """Frames through the processor every command runs (analyze's least squares, or the carrier method)."""
    settings = InterferometerSettings(method=method, fit=FitSettings(method="circle", modes=11, dtype="float64"))
    return measure_set(list(frames), settings)



def optic_with(surface: SurfaceSettings | None = SURFACE, **changes) -> TestOptic:
    values = dict(aperture=CIRCLE, zernike_waves=(0.0,), noise_rms=0.0, bit_depth=16, surface=surface)
    values.update(changes)
    return TestOptic(OpticSettings(**values), SIZE, SIZE)


def measured_heights_nm(optic: TestOptic) -> tuple[np.ndarray, OpticTruth]:
    """Four phase-shifted frames -> phase -> unwrapped wavefront -> surface heights (nm), piston-free."""
    frames = []
    for step in STEPS:
        frame, truth = optic.interferogram(0.0, step)
        frames.append(frame)
    phase = phase_from_frames(np.stack(frames), method="lsq", steps=STEPS).phase
    waves = unwrap_spatial(phase, truth.mask) / (2 * np.pi)
    heights = wavefront_to_surface(waves * WAVELENGTH_NM, 0.5)
    return heights - np.nanmean(heights), truth


def piston_free(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask, values - values[mask].mean(), np.nan)


def test_phase_pipeline_gives_back_the_surface_heights() -> None:
    optic = optic_with()
    heights, truth = measured_heights_nm(optic)
    assert truth.surface_revision == 0 and truth.surface_nm is optic.surface.heights_nm()
    error = heights - piston_free(truth.surface_nm, truth.mask)
    assert np.nanmax(np.abs(error)) < PIXEL_TOL_NM
    # the wavefront in the truth is 2 x heights / wavelength (zernike_waves all zero)
    inside = truth.mask
    np.testing.assert_allclose(truth.wavefront_waves[inside], 2.0 * truth.surface_nm[inside] / WAVELENGTH_NM,
                               atol=1e-12)
    assert np.all(np.isnan(truth.wavefront_waves[~inside]))


def test_surface_zernike_terms_use_the_optic_normalisation() -> None:
    optic = optic_with(SurfaceSettings(zernike_nm=SURFACE.zernike_nm, wavelength_nm=WAVELENGTH_NM),
                       zernike_waves=(0.0, 0.0, 0.0, 0.1))
    frames = np.stack([optic.interferogram(0.0, step)[0] for step in STEPS])
    truth = optic.truth(0.0)
    measured = measured_set(frames)
    fitter = build_fitter(measured.aperture, modes=11, dtype=np.float64, pupil=truth.pupil_px)
    coefficients = fitter.fit(measured.waves, nan_policy="omit").coefficients
    expected = np.zeros(11)
    expected[3] = 0.1 + 2.0 * 40.0 / WAVELENGTH_NM  # the optic's own defocus plus the surface's
    expected[7] = 2.0 * 12.0 / WAVELENGTH_NM
    error = coefficients - expected
    error[0] -= np.round(error[0])
    assert np.max(np.abs(error)) < PIXEL_TOL_WAVES


def test_removal_changes_the_next_frame_and_never_a_snapshot() -> None:
    optic = optic_with()
    state = optic.surface
    frame_before, truth_before = optic.interferogram(0.0, 0.0)
    snapshot = state.heights_nm()
    kept = snapshot.copy()
    rows, cols = np.indices((SIZE, SIZE))
    removal = 8.0 * np.exp(-((cols - 140.0) ** 2 + (rows - 110.0) ** 2) / (2 * 15.0**2))  # a tool's footprint
    state.apply_removal(removal)
    frame_after, truth_after = optic.interferogram(0.0, 0.0)
    assert (truth_before.surface_revision, truth_after.surface_revision) == (0, 1)
    assert np.any(frame_after != frame_before)
    np.testing.assert_array_equal(snapshot, kept)
    np.testing.assert_array_equal(truth_before.surface_nm, kept)  # a truth handed out keeps its surface
    np.testing.assert_allclose(truth_after.surface_nm, kept - removal, atol=1e-12)
    # and the pipeline sees exactly the removal (within the aperture, piston-free)
    heights, _ = measured_heights_nm(optic)
    expected = piston_free(kept - removal, truth_after.mask)
    assert np.nanmax(np.abs(heights - expected)) < PIXEL_TOL_NM


def test_unchanged_surface_is_rendered_from_the_cache() -> None:
    optic = optic_with()
    first, second = optic.truth(0.0), optic.truth(0.5)
    assert second.wavefront_waves is first.wavefront_waves  # no drift, same revision: nothing re-made
    optic.surface.apply_removal(np.zeros((SIZE, SIZE)))
    third = optic.truth(0.0)
    assert third.wavefront_waves is not first.wavefront_waves and third.surface_revision == 1
    np.testing.assert_array_equal(third.wavefront_waves, first.wavefront_waves)


def test_drift_adds_to_the_surface() -> None:
    drift = (0.0, 0.0, 0.0, 0.02)
    optic = optic_with(zernike_waves=(0.0, 0.0, 0.0, 0.0), drift_waves_per_s=drift)
    still = optic_with(zernike_waves=(0.0, 0.0, 0.0, 0.0))
    later, now = optic.truth(3.0), still.truth(3.0)
    moved = later.wavefront_waves - now.wavefront_waves
    assert not np.allclose(moved[later.mask], 0.0)
    # W(t) = surface + t D: the frames at t follow it, the surface the same in both
    frame = optic.interferogram(3.0, 0.0)[0]
    expected = still.interferogram(3.0, 0.0)[0]
    assert np.any(frame != expected)
    np.testing.assert_array_equal(later.surface_nm, now.surface_nm)


def test_new_aperture_shows_the_same_surface() -> None:
    optic = optic_with()
    state, before = optic.surface, optic.truth(0.0)
    optic.set_aperture(ANNULUS)
    after = optic.truth(0.0)
    assert optic.surface is state and after.surface_revision == 0 and after.aperture_revision == 1
    assert after.surface_nm is before.surface_nm
    inside = after.mask
    np.testing.assert_allclose(after.wavefront_waves[inside], 2.0 * state.heights_nm()[inside] / WAVELENGTH_NM,
                               atol=1e-12)
    heights, truth = measured_heights_nm(optic)
    assert np.nanmax(np.abs(heights - piston_free(truth.surface_nm, truth.mask))) < PIXEL_TOL_NM


def test_optic_without_surface_has_none() -> None:
    optic = optic_with(surface=None)
    truth = optic.interferogram(0.0)[1]
    assert optic.surface is None and truth.surface_revision is None and truth.surface_nm is None


def test_surface_settings_are_checked_by_the_optic_settings() -> None:
    with pytest.raises(ValueError, match="surface: expected SurfaceSettings"):
        OpticSettings(surface={"zernike_nm": (1.0,)})  # type: ignore[arg-type]


def test_reflection_factor_and_wavelength_scale_the_wavefront() -> None:
    single = SurfaceSettings(zernike_nm=(0.0, 0.0, 0.0, 40.0), reflection_factor=1.0, wavelength_nm=500.0)
    truth = optic_with(single).truth(0.0)
    inside = truth.mask
    np.testing.assert_allclose(truth.wavefront_waves[inside], truth.surface_nm[inside] / 500.0, atol=1e-12)
    assert math.isclose(float(np.nanmax(truth.wavefront_waves)), float(truth.surface_nm[inside].max()) / 500.0)


def test_a_zernike_surface_renders_as_the_same_zernike_wavefront_with_carrier() -> None:
    waves = (0.0, 0.0, 0.0, 0.3, 0.1, -0.1, 0.05)
    as_surface = SurfaceSettings(zernike_nm=tuple(c * WAVELENGTH_NM / 2.0 for c in waves), wavelength_nm=WAVELENGTH_NM)
    carrier = (40.0, 10.0)
    surfaced = optic_with(as_surface, carrier_cycles=carrier)
    plain = optic_with(None, zernike_waves=waves, carrier_cycles=carrier)
    for shift in (0.0, 1.1):
        frame, truth = surfaced.interferogram(0.0, shift)
        expected, plain_truth = plain.interferogram(0.0, shift)
        # the same phase summed in another order: float32 rounding may move a count either way
        assert np.max(np.abs(frame.astype(np.int64) - expected)) <= 1
        np.testing.assert_allclose(truth.wavefront_waves[truth.mask], plain_truth.wavefront_waves[truth.mask],
                                   atol=1e-12)
