"""Tests for wavestack.simulators.spots: Shack-Hartmann frames read back by the pipeline.

The sensor: a 1280 x 1024 camera (5.5 um pixels) behind lenslets of pitch 25 px and focal length
5 mm at 632.8 nm, so ``gain = f lambda / p^2 = 104.6`` px per wave/px; the optic's pupil, a disk
of radius 490 px centred on the camera, 16-bit frames.

Tolerances
----------
* Exact geometry: a tilt has a constant gradient and defocus a linear one, whose mean over a
  square equals the value at its centre, which the midpoint sub-sampling reproduces up to
  rounding: 1e-9 px.
* Centroids: the pipeline's thresholded centre of gravity has a pixel-phase bias up to 0.005 px
  for sigma = 1.5 px spots (its docstring); the read noise (0.0005 of full scale = 33 counts on
  spots of 4.6e5 counts) adds about sigma_r sqrt(sum dx^2) / flux = 33 * 11 / 4.6e5 = 8e-4 px
  RMS. Bound: 0.015 px (bias plus more than 10 noise RMS).
* Modal reconstruction: the reconstructor uses gradients at lenslet centres, the spots the mean
  over each subaperture; that model error is computed by reconstructing the true slopes. The
  centroid errors (RMS e px) add ``e / gain * ||row_k||_2`` RMS to coefficient k; we allow the
  model error plus 5 of those plus 1e-4 waves.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from wavestack.pipeline import Centroider, LensletLattice, convert_slopes, slopes
from wavestack.pipeline import ModalReconstructor
from wavestack.simulators.optic import ApertureShape, OpticSettings, TestOptic
from wavestack.simulators.spots import LensletArraySettings, SpotRenderer, SpotTruth

HEIGHT, WIDTH = 1024, 1280
FOCAL_UM, PIXEL_UM, WAVELENGTH_UM = 5000.0, 5.5, 0.6328
GAIN = FOCAL_UM * WAVELENGTH_UM / PIXEL_UM**2
PUPIL = ApertureShape(centre_px=(640.0, 512.0), radius_px=490.0)
COEFFICIENTS = (0.0, 0.3, -0.2, 0.5, 0.1, -0.2, 0.1, 0.05, 0.03, -0.02, 0.25)  # waves, Noll 1..11
LENSLETS = LensletArraySettings(
    pitch_px=25.0, offset_px=(140.0, 12.0), gain_px=LensletArraySettings.gain_for(FOCAL_UM, PIXEL_UM, WAVELENGTH_UM),
    noise_rms=0.0005, bit_depth=16,
)
CENTROID_TOL_PX = 0.015
EXACT_PX = 1e-9


def renderer_for(coefficients, lenslets: LensletArraySettings = LENSLETS, **optic) -> SpotRenderer:
    settings = OpticSettings(aperture=PUPIL, zernike_waves=tuple(coefficients), **optic)
    return SpotRenderer(TestOptic(settings, HEIGHT, WIDTH), lenslets, HEIGHT, WIDTH)


def grid_of(renderer: SpotRenderer) -> LensletLattice:
    """The pipeline's description of the simulated array (written apart from the simulator's)."""
    lenslets = renderer.lenslets
    half = lenslets.pitch_px / 2
    first = (lenslets.offset_px[0] + half, lenslets.offset_px[1] + half)
    return LensletLattice.array(lenslets.lattice, lenslets.pitch_px, renderer.grid_shape, first_centre_px=first,
                                orientation_deg=lenslets.orientation_deg)


def measure(renderer: SpotRenderer, frame: np.ndarray, truth: SpotTruth):
    return Centroider.build(grid_of(renderer), frame.shape, mask=truth.valid).measure(frame)


@pytest.fixture(scope="module")
def aberrated():
    renderer = renderer_for(COEFFICIENTS)
    frame, truth = renderer.spot_frame(0.0)
    return renderer, frame, truth


def test_gain_from_optics() -> None:
    assert math.isclose(LENSLETS.gain_px, GAIN, rel_tol=1e-15)
    assert 104 < GAIN < 105


def test_grid_matches_the_pipeline_grid(aberrated) -> None:
    renderer, frame, truth = aberrated
    assert renderer.grid_shape == (40, 45)  # whole 25 px lenslets from (140, 12) in 1280 x 1024
    np.testing.assert_array_equal(truth.centres_px, grid_of(renderer).centres())
    assert frame.shape == (HEIGHT, WIDTH) and frame.dtype == np.uint16


def test_tilt_moves_every_spot_by_gain_times_slope() -> None:
    tilt = 0.4
    for noll, column in ((2, 0), (3, 1)):
        coefficients = np.zeros(3)
        coefficients[noll - 1] = tilt
        _, truth = renderer_for(coefficients).spot_frame(0.0)
        radius = truth.pupil_px[2]
        # Z2 = 2 u, Z3 = 2 v with u = x / R: dW/dx (or dW/dy, y up) = 2 tilt / R waves per pixel
        slope = 2 * tilt / radius
        lit = truth.fill > 0
        expected = np.zeros((lit.sum(), 2))
        expected[:, column] = GAIN * slope * (1 if column == 0 else -1)  # y up: rows move the other way
        np.testing.assert_allclose(truth.displacements_px[lit], expected, atol=EXACT_PX)
        np.testing.assert_allclose(truth.positions_px, truth.centres_px + truth.displacements_px, atol=0)


def test_defocus_moves_spots_radially_outward() -> None:
    defocus = 0.5
    _, truth = renderer_for((0.0, 0.0, 0.0, defocus)).spot_frame(0.0)
    cx, cy, radius = truth.pupil_px
    # Z4 = sqrt(3) (2 rho^2 - 1): grad = 4 sqrt(3) (u, v) / R per pixel, v up; mean over a full
    # square = value at its centre (linear gradient)
    full = truth.fill == 1.0
    centres = truth.centres_px[full]
    factor = GAIN * 4 * math.sqrt(3) * defocus / radius**2
    expected = np.column_stack([factor * (centres[:, 0] - cx), factor * (centres[:, 1] - cy)])
    np.testing.assert_allclose(truth.displacements_px[full], expected, atol=EXACT_PX)
    np.testing.assert_array_equal(truth.valid, full)  # min_fill = 1 by default


def test_flat_wavefront_spots_sit_on_the_lenslet_centres() -> None:
    renderer = renderer_for((0.7,))  # piston only: no slope anywhere
    frame, truth = renderer.spot_frame(0.0)
    np.testing.assert_array_equal(truth.positions_px, truth.centres_px)
    spots = measure(renderer, frame, truth)
    error = spots.centroids[truth.valid] - truth.centres_px[truth.valid]
    assert np.all(spots.valid == truth.valid)
    assert np.max(np.abs(error)) < CENTROID_TOL_PX


def test_centroids_match_true_spot_positions(aberrated) -> None:
    renderer, frame, truth = aberrated
    assert np.max(np.abs(truth.displacements_px)) > 2.0  # a real aberration, not a flat frame
    spots = measure(renderer, frame, truth)
    assert np.all(spots.valid == truth.valid) and truth.valid.sum() > 1000
    error = spots.centroids[truth.valid] - truth.positions_px[truth.valid]
    assert np.max(np.abs(error)) < CENTROID_TOL_PX


def test_modal_reconstruction_returns_the_optic_coefficients(aberrated) -> None:
    renderer, frame, truth = aberrated
    grid = grid_of(renderer)
    spots = measure(renderer, frame, truth)
    result = slopes(spots, grid.centres(), focal_length_um=FOCAL_UM, pixel_um=PIXEL_UM)
    slope_x, slope_y = convert_slopes(result, wavefront_unit_um=WAVELENGTH_UM, length_unit_um=PIXEL_UM)
    cx, cy, radius = truth.pupil_px
    reconstructor = ModalReconstructor.for_circle(grid.centres_xy(), (cx, -cy), radius, truth.modes, truth.valid)
    found = reconstructor.reconstruct(slope_x, slope_y)
    # the model error: the same reconstruction from the exact subaperture-mean slopes
    exact = reconstructor.reconstruct(truth.slopes_waves_per_px[:, 0], truth.slopes_waves_per_px[:, 1])
    model_error = np.abs(exact - truth.coefficients_waves)
    assert np.max(model_error[1:]) < 0.005  # (pitch / R)^2 effects stay small against 0.1-0.5 waves
    centroid_rms = float(np.sqrt(np.mean((spots.centroids - truth.positions_px)[truth.valid] ** 2)))
    noise = 5 * centroid_rms / GAIN * np.linalg.norm(reconstructor.matrix, axis=1)
    error = np.abs(found - truth.coefficients_waves)
    assert np.all(error[1:] <= model_error[1:] + noise[1:] + 1e-4)  # piston is not sensed


def test_dark_and_partial_lenslets() -> None:
    renderer = renderer_for(COEFFICIENTS, replace(LENSLETS, min_fill=0.5))
    frame, truth = renderer.spot_frame(0.0)
    cx, cy, radius = 640.0, 512.0, 490.0
    half = renderer.lenslets.pitch_px / 2
    centres = truth.centres_px
    # a square whose farthest corner is inside the circle is fully lit; one whose nearest point
    # is outside it is dark
    far = np.hypot(np.abs(centres[:, 0] - cx) + half, np.abs(centres[:, 1] - cy) + half)
    near = np.hypot(np.maximum(np.abs(centres[:, 0] - cx) - half, 0), np.maximum(np.abs(centres[:, 1] - cy) - half, 0))
    assert np.all(truth.fill[far < radius] == 1.0)
    assert np.all(truth.fill[near > radius] == 0.0)
    np.testing.assert_array_equal(truth.valid, truth.fill >= 0.5)
    assert np.any((truth.fill > 0) & (truth.fill < 0.5))  # partial lenslets exist and are not valid
    # dark lenslets show only background and noise: 0.02 FS, noise 0.0005 FS, far below a spot
    grid = grid_of(renderer)
    row_starts, col_starts, width = grid.window_starts()
    full = 65535
    for k in np.flatnonzero(truth.fill == 0)[:50]:
        window = frame[row_starts[k] : row_starts[k] + width, col_starts[k] : col_starts[k] + width]
        assert window.max() < (0.02 + 6 * 0.0005) * full
    # a fully lit spot peaks near 0.5 FS above the background (pixel integration lowers the peak)
    k = int(np.flatnonzero(truth.fill == 1.0)[0])
    window = frame[row_starts[k] : row_starts[k] + width, col_starts[k] : col_starts[k] + width]
    assert 0.3 * full < window.max() - 0.02 * full < 0.5 * full


def test_aperture_change_reaches_the_spots() -> None:
    renderer = renderer_for(COEFFICIENTS)
    _, before = renderer.spot_frame(0.0)
    hole = ApertureShape(kind="annulus", centre_px=(640.0, 512.0), radius_px=490.0, inner_radius_px=150.0,
                         obscuration_centre_px=(600.0, 540.0))
    renderer.optic.set_aperture(hole)  # the station changes the optic it shares with the camera
    frame, after = renderer.spot_frame(0.0)
    assert before.aperture_revision == 0 and after.aperture_revision == 1
    inside_hole = np.hypot(after.centres_px[:, 0] - 600.0, after.centres_px[:, 1] - 540.0) < 150.0 - 12.5 * math.sqrt(2)
    assert np.all(before.fill[inside_hole] == 1.0) and np.all(after.fill[inside_hole] == 0.0)
    assert after.valid.sum() < before.valid.sum()
    spots = measure(renderer, frame, after)
    error = spots.centroids[after.valid] - after.positions_px[after.valid]
    assert np.max(np.abs(error)) < CENTROID_TOL_PX


def test_relay_magnification_and_shift() -> None:
    settings = OpticSettings(aperture=ApertureShape(centre_px=(256.0, 256.0), radius_px=200.0),
                             zernike_waves=COEFFICIENTS, noise_rms=0.0)
    optic = TestOptic(settings, 512, 512)
    relay = replace(LENSLETS, magnification=2.2, pupil_shift_px=(76.8, -51.2))
    renderer = SpotRenderer(optic, relay, HEIGHT, WIDTH)
    frame, truth = renderer.spot_frame(0.0)
    cx, cy, radius = optic.pupil_px
    np.testing.assert_allclose(truth.pupil_px, (2.2 * cx + 76.8, 2.2 * cy - 51.2, 2.2 * radius), rtol=1e-15)
    grid = grid_of(renderer)
    spots = measure(renderer, frame, truth)
    result = slopes(spots, grid.centres(), focal_length_um=FOCAL_UM, pixel_um=PIXEL_UM)
    slope_x, slope_y = convert_slopes(result, wavefront_unit_um=WAVELENGTH_UM, length_unit_um=PIXEL_UM)
    pcx, pcy, pradius = truth.pupil_px
    found = ModalReconstructor.for_circle(grid.centres_xy(), (pcx, -pcy), pradius, truth.modes, truth.valid
                                          ).reconstruct(slope_x, slope_y)
    # same budget as the unmagnified case (radius 440 px on the camera, similar lenslet count)
    np.testing.assert_allclose(found[1:], truth.coefficients_waves[1:], atol=0.005)


def test_drift_and_determinism() -> None:
    drift = (0.0, 0.02) + (0.0,) * 9
    first = renderer_for(COEFFICIENTS, drift_waves_per_s=drift)
    second = renderer_for(COEFFICIENTS, drift_waves_per_s=drift)
    for t in (0.0, 3.0):
        a, truth = first.spot_frame(t)
        b, _ = second.spot_frame(t)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(truth.coefficients_waves, np.add(COEFFICIENTS, t * np.array(drift)), atol=1e-15)
    _, start = first.spot_frame(0.0)
    lit = start.fill > 0
    # 3 s of x-tilt drift moves every spot by gain * 2 * 0.06 / R columns more
    shift = (truth.displacements_px - start.displacements_px)[lit]
    np.testing.assert_allclose(shift[:, 0], GAIN * 2 * 0.06 / start.pupil_px[2], atol=EXACT_PX)
    np.testing.assert_allclose(shift[:, 1], 0.0, atol=EXACT_PX)
    other = renderer_for(COEFFICIENTS, replace(LENSLETS, seed=9),
                         drift_waves_per_s=drift)
    assert np.any(other.spot_frame(3.0)[0] != a)


def test_eight_bit_frames() -> None:
    lenslets = replace(LENSLETS, bit_depth=8)
    frame, _ = renderer_for(COEFFICIENTS, lenslets).spot_frame(0.0)
    assert frame.dtype == np.uint8 and frame.max() > 100


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(pitch_px=3.0), "pitch_px"),
        (dict(gain_px=0.0), "gain_px"),
        (dict(min_fill=0.0), "min_fill"),
        (dict(fill_samples=1), "fill_samples"),
        (dict(grid_shape=(0, 4)), "grid_shape"),
        (dict(bit_depth=14), "bit_depth"),
    ],
)
def test_settings_reject_bad_fields(kwargs: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        LensletArraySettings(**kwargs)


def test_grid_that_does_not_fit_is_rejected() -> None:
    optic = TestOptic(OpticSettings(aperture=ApertureShape(centre_px=(32.0, 32.0), radius_px=20.0)), 64, 64)
    with pytest.raises(ValueError, match="grid_shape"):
        SpotRenderer(optic, LensletArraySettings(pitch_px=10.0, grid_shape=(7, 7)), 64, 64)
