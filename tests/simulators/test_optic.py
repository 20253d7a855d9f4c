"""Tests for wavestack.simulators.optic: aperture masks, ground truth, and frames the pipeline reads back.

Tolerances
----------
* Mask areas: a pixel counts when its centre is inside, so the union of counted pixel squares
  differs from the shape only within ``d = sqrt(2) / 2`` px of the boundary (a point of one and
  not the other lies in a pixel whose centre is on the other side). That band has area at most
  ``2 d P`` for a circle or ellipse (Steiner's tube formula, P the boundary length) plus
  ``pi d^2`` per vertex for polygons (each edge's neighbourhood is a stadium of area
  ``2 d l + pi d^2``), which bounds ``|count - area|``.
* Phase shifting, noise off, 16 bits: each frame is rounded to +-0.5 count, so the four-step
  quadratures ``(I0 - I2) / 2`` and ``(I3 - I1) / 2`` are off by <= 0.5 count each and the phase by
  <= atan(0.71 / B) with ``B = 0.4 * 65535``: 2.7e-5 rad = 4.3e-6 waves; the float32 rendering
  (phase wrapped to [0, 2 pi), float32 cos) adds < 1e-6 rad. Bound used: 1e-5 waves, per pixel
  and per coefficient (for a nearly orthonormal basis a coefficient error is at most the largest
  pixel error).
* Carrier (Fourier) method: it is not exact. The sideband window and the edge taper leave errors
  within about two fringe periods of the aperture edge; away from it (8 px, two periods of the
  60-fringe carrier) we measured 0.0014 waves RMS and 0.0047 waves peak after removing piston
  and tilt (the carrier estimate absorbs the wavefront's mean tilt). Bounds: 0.005 RMS, 0.015 peak.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.pipeline import build_fitter, mode_list, phase_from_frames, unwrap_spatial, zernike_basis
from wavestack.pipeline import Aperture
from wavestack.pipeline import FitSettings, InterferometerOutcome, InterferometerSettings, measure_set
from wavestack.simulators.optic import ApertureShape, OpticSettings, OpticTruth, TestOptic

SIZE = 256
COEFFICIENTS = (0.3, 0.0, 0.0, 0.8, 0.2, -0.3, 0.15, 0.1, 0.05, -0.04, 0.3)  # waves, Noll 1..11
CIRCLE = ApertureShape(centre_px=(130.3, 124.8), radius_px=110.0)
ANNULUS = ApertureShape(
    kind="annulus", centre_px=(128.4, 127.9), radius_px=100.0, inner_radius_px=30.0,
    obscuration_centre_px=(140.2, 110.5),
)
STEPS = np.arange(4) * np.pi / 2
PIXEL_TOL_WAVES = 1e-5
DELTA = math.sqrt(2.0) / 2.0

def measured_set(frames: np.ndarray, method: str = "psi") -> InterferometerOutcome:
    """Frames through the processor every command runs (analyze's least squares, or the carrier method)."""
    settings = InterferometerSettings(method=method, fit=FitSettings(method="circle", modes=11, dtype="float64"))
    return measure_set(list(frames), settings)



def clean_settings(**changes) -> OpticSettings:
    """Noise-free 16-bit settings on the circle aperture (the exact-recovery configuration)."""
    values = dict(aperture=CIRCLE, zernike_waves=COEFFICIENTS, noise_rms=0.0, bit_depth=16)
    values.update(changes)
    return OpticSettings(**values)


def four_frames(optic: TestOptic, time_s: float = 0.0) -> tuple[np.ndarray, OpticTruth]:
    frames = []
    for step in STEPS:
        frame, truth = optic.interferogram(time_s, step)
        frames.append(frame)
    return np.stack(frames), truth


# --------------------------------------------------------------------------- masks


def polygon_area_and_perimeter(vertices: np.ndarray) -> tuple[float, float]:
    x, y = vertices[:, 0], vertices[:, 1]
    area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    perimeter = float(np.sum(np.hypot(np.diff(x, append=x[0]), np.diff(y, append=y[0]))))
    return area, perimeter


ARROW = ((40.5, 60.2), (150.3, 60.2), (150.3, 30.7), (220.8, 110.1), (150.3, 190.4), (150.3, 160.6),
         (40.5, 160.6), (90.2, 110.1))  # non-convex: the notch at (90.2, 110.1)


@pytest.mark.parametrize(
    "shape, area, perimeter, vertices",
    [
        (ApertureShape(centre_px=(100.3, 90.7), radius_px=70.2), math.pi * 70.2**2, 2 * math.pi * 70.2, 0),
        (ANNULUS, math.pi * (100.0**2 - 30.0**2), 2 * math.pi * 130.0, 0),
        # perimeter of an ellipse <= pi sqrt(2 (a^2 + b^2)) (a classical upper bound)
        (ApertureShape(kind="ellipse", centre_px=(128.0, 120.5), semi_axes_px=(90.0, 45.0), rotation_deg=30.0),
         math.pi * 90 * 45, math.pi * math.sqrt(2 * (90.0**2 + 45.0**2)), 0),
        (ApertureShape(kind="rectangle", centre_px=(127.2, 131.9), semi_axes_px=(80.0, 35.0), rotation_deg=-20.0),
         4 * 80 * 35, 4 * (80 + 35), 4),
        (ApertureShape(kind="polygon", vertices_px=ARROW), *polygon_area_and_perimeter(np.array(ARROW)), len(ARROW)),
    ],
    ids=["circle", "annulus", "ellipse", "rectangle", "polygon"],
)
def test_mask_area_matches_analytic_area(shape: ApertureShape, area: float, perimeter: float, vertices: int) -> None:
    mask = shape.mask(SIZE, SIZE)
    assert mask.shape == (SIZE, SIZE) and mask.dtype == np.bool_
    bound = 2 * DELTA * perimeter + math.pi * DELTA**2 * max(vertices, 1)
    assert abs(int(mask.sum()) - area) <= bound


def test_masks_are_pixel_centres_inside() -> None:
    rows, cols = np.indices((SIZE, SIZE))
    circle = ApertureShape(centre_px=(100.3, 90.7), radius_px=70.2)
    np.testing.assert_array_equal(circle.mask(SIZE, SIZE), (cols - 100.3) ** 2 + (rows - 90.7) ** 2 <= 70.2**2)
    expected_annulus = (((cols - 128.4) ** 2 + (rows - 127.9) ** 2 <= 100.0**2)
                        & ((cols - 140.2) ** 2 + (rows - 110.5) ** 2 > 30.0**2))
    np.testing.assert_array_equal(ANNULUS.mask(SIZE, SIZE), expected_annulus)
    # a 30 degree ellipse: first axis along (cos 30, sin 30) with y up, i.e. towards -row
    ellipse = ApertureShape(kind="ellipse", centre_px=(128.0, 120.5), semi_axes_px=(90.0, 45.0), rotation_deg=30.0)
    dx, dy = cols - 128.0, 120.5 - rows
    along = dx * math.cos(math.pi / 6) + dy * math.sin(math.pi / 6)
    across = -dx * math.sin(math.pi / 6) + dy * math.cos(math.pi / 6)
    np.testing.assert_array_equal(ellipse.mask(SIZE, SIZE), (along / 90.0) ** 2 + (across / 45.0) ** 2 <= 1.0)
    assert ellipse.mask(SIZE, SIZE)[int(120.5 - 70 * 0.5), int(128 + 70 * math.cos(math.pi / 6))]  # up-right
    # the non-convex polygon against OpenCV's independent point-in-polygon test
    polygon = ApertureShape(kind="polygon", vertices_px=ARROW).mask(SIZE, SIZE)
    contour = np.array(ARROW, dtype=np.float32).reshape(-1, 1, 2)
    for row in range(0, SIZE, 3):
        for col in range(0, SIZE, 3):
            side = cv2.pointPolygonTest(contour, (float(col), float(row)), False)
            if side != 0:  # exact ties on an edge are left to the rule
                assert polygon[row, col] == (side > 0), (row, col)
    assert not polygon[110, 70]  # inside the notch's bounding box but outside the polygon


@settings(max_examples=25, deadline=None)
@given(
    cx=st.floats(60, 190), cy=st.floats(60, 190), a=st.floats(5, 60), b=st.floats(5, 60),
    rotation=st.floats(-180, 180),
)
def test_rectangle_equals_its_polygon(cx: float, cy: float, a: float, b: float, rotation: float) -> None:
    rectangle = ApertureShape(kind="rectangle", centre_px=(cx, cy), semi_axes_px=(a, b), rotation_deg=rotation)
    t = math.radians(rotation)
    ex, ey = (math.cos(t), -math.sin(t)), (-math.sin(t), -math.cos(t))  # (col, row) of the axes
    corners = tuple((cx + sa * a * ex[0] + sb * b * ey[0], cy + sa * a * ex[1] + sb * b * ey[1])
                    for sa, sb in ((1, 1), (-1, 1), (-1, -1), (1, -1)))
    polygon = ApertureShape(kind="polygon", vertices_px=corners)
    rows, cols = np.indices((SIZE, SIZE))
    dx, dy = cols - cx, cy - rows
    along = dx * math.cos(t) + dy * math.sin(t)
    across = -dx * math.sin(t) + dy * math.cos(t)
    on_edge = (np.abs(np.abs(along) - a) < 1e-6) | (np.abs(np.abs(across) - b) < 1e-6)
    differ = rectangle.mask(SIZE, SIZE) != polygon.mask(SIZE, SIZE)
    assert not np.any(differ & ~on_edge)  # they may only disagree on pixel centres on an edge


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(kind="hexagon"), "kind"),
        (dict(radius_px=0.0), "radius_px"),
        (dict(kind="annulus", inner_radius_px=500.0), "inner_radius_px"),
        (dict(kind="annulus", inner_radius_px=50.0, obscuration_centre_px=(900.0, 512.0)), "obscuration_centre_px"),
        (dict(kind="ellipse", semi_axes_px=(10.0, -1.0)), "semi_axes_px"),
        (dict(kind="polygon", vertices_px=((0.0, 0.0), (1.0, 1.0))), "vertices_px"),
        (dict(centre_px=(float("nan"), 1.0)), "centre_px"),
    ],
)
def test_aperture_shape_rejects_bad_fields(kwargs: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        ApertureShape(**kwargs)


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(zernike_waves=()), "zernike_waves"),
        (dict(zernike_waves=(0.0, 1.0), drift_waves_per_s=(0.1,)), "drift_waves_per_s"),
        (dict(bit_depth=10), "bit_depth"),
        (dict(noise_rms=-0.1), "noise_rms"),
        (dict(carrier_cycles=(1.0,)), "carrier_cycles"),
        (dict(seed=-1), "seed"),
    ],
)
def test_optic_settings_reject_bad_fields(kwargs: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        OpticSettings(**kwargs)


def test_empty_aperture_is_rejected() -> None:
    outside = ApertureShape(centre_px=(-100.0, -100.0), radius_px=10.0)
    with pytest.raises(ValueError, match="covers no pixel"):
        TestOptic(OpticSettings(aperture=outside), 64, 64)


# --------------------------------------------------------------------------- truth


def test_truth_is_the_documented_zernike_sum_on_the_enclosing_disk() -> None:
    optic = TestOptic(clean_settings(), SIZE, SIZE)
    truth = optic.truth(0.0)
    np.testing.assert_array_equal(truth.mask, CIRCLE.mask(SIZE, SIZE))
    assert truth.pupil_px == Aperture.from_mask(truth.mask).enclosing_circle()
    cx, cy, radius = truth.pupil_px
    # the enclosing circle of the pixel centres of a disk of radius 110 px: within a pixel of it
    assert abs(cx - 130.3) < 1 and abs(cy - 124.8) < 1 and 109 < radius <= 110
    assert truth.modes == tuple(mode_list("noll", len(COEFFICIENTS)))
    np.testing.assert_array_equal(truth.coefficients_waves, COEFFICIENTS)
    rows, cols = np.nonzero(truth.mask)
    expected = zernike_basis(truth.modes, (cols - cx) / radius, (cy - rows) / radius) @ np.array(COEFFICIENTS)
    np.testing.assert_allclose(truth.wavefront_waves[rows, cols], expected, atol=1e-12)
    assert np.all(np.isnan(truth.wavefront_waves[~truth.mask]))
    assert truth.phase_shift_rad == 0.0 and truth.vibration_rad == 0.0
    with pytest.raises(ValueError):
        truth.wavefront_waves[rows[0], cols[0]] = 0.0  # shared, read-only


def test_linear_drift_of_coefficients_and_map() -> None:
    drift = (0.0, 0.01, 0.0, -0.02) + (0.0,) * 6 + (0.005,)
    optic = TestOptic(clean_settings(drift_waves_per_s=drift), SIZE, SIZE)
    start, later = optic.truth(0.0), optic.truth(2.5)
    np.testing.assert_allclose(later.coefficients_waves, np.add(COEFFICIENTS, 2.5 * np.array(drift)), atol=1e-15)
    one = optic.truth(1.0).wavefront_waves
    # the map is linear in time: W(2.5) = W(0) + 2.5 (W(1) - W(0))
    inside = start.mask
    np.testing.assert_allclose(later.wavefront_waves[inside],
                               start.wavefront_waves[inside] + 2.5 * (one - start.wavefront_waves)[inside], atol=1e-12)
    # and the frames follow: the four-step phase at t = 2.5 s is the drifted wavefront
    frames, truth = four_frames(optic, 2.5)
    phase = unwrap_spatial(phase_from_frames(frames, method="lsq", steps=STEPS).phase, truth.mask)
    error = phase / (2 * np.pi) - later.wavefront_waves
    error -= np.round(np.nanmedian(error))
    assert np.nanmax(np.abs(error)) < PIXEL_TOL_WAVES


# --------------------------------------------------------------------------- frames


def test_four_step_frames_give_back_the_wavefront() -> None:
    optic = TestOptic(clean_settings(), SIZE, SIZE)
    frames, truth = four_frames(optic)
    assert frames.dtype == np.uint16
    result = phase_from_frames(frames, method="lsq", steps=STEPS)
    unwrapped = unwrap_spatial(result.phase, truth.mask)
    error = unwrapped / (2 * np.pi) - truth.wavefront_waves
    error -= np.round(np.nanmedian(error))  # unwrapping fixes the phase only up to 2 pi k
    assert np.nanmax(np.abs(error)) < PIXEL_TOL_WAVES


def test_measurement_chain_recovers_the_coefficients() -> None:
    optic = TestOptic(clean_settings(), SIZE, SIZE)
    frames, truth = four_frames(optic)
    measured = measured_set(frames)
    assert not np.any(measured.aperture.mask & ~truth.mask)  # detected inside the true aperture
    fitter = build_fitter(measured.aperture, modes=len(COEFFICIENTS), dtype=np.float64, pupil=truth.pupil_px)
    error = fitter.fit(measured.waves, nan_policy="omit").coefficients - truth.coefficients_waves
    error[0] -= np.round(error[0])  # piston is known modulo one wave
    assert np.max(np.abs(error)) < PIXEL_TOL_WAVES


def test_carrier_frame_gives_back_the_wavefront() -> None:
    gentle = (0.3, 0.0, 0.0, 0.25, 0.1, -0.1, 0.06, 0.04, 0.02, -0.02, 0.08)  # local fringes stay in the window
    optic = TestOptic(clean_settings(zernike_waves=gentle, carrier_cycles=(60.0, 15.0)), SIZE, SIZE)
    frame, truth = optic.interferogram(0.0)
    assert truth.carrier_cycles == (60.0, 15.0)
    measured = measured_set([frame], "carrier")  # nx > 0: the default sideband gives +W
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (17, 17))
    interior = cv2.erode(truth.mask.astype(np.uint8), kernel).astype(bool) & np.isfinite(measured.waves)
    assert interior.sum() > 0.8 * cv2.erode(truth.mask.astype(np.uint8), kernel).sum()
    error = (measured.waves - truth.wavefront_waves)[interior]
    rows, cols = np.nonzero(interior)
    plane = np.column_stack([np.ones(rows.size), cols, rows])
    error -= plane @ np.linalg.lstsq(plane, error, rcond=None)[0]
    assert np.sqrt(np.mean(error**2)) < 0.005
    assert np.max(np.abs(error)) < 0.015


def test_vibration_is_a_piston_added_to_the_phase() -> None:
    frequency, rms = 7.0, 0.3
    shaking = TestOptic(clean_settings(vibration_rms_rad=rms, vibration_hz=frequency), SIZE, SIZE)
    still = TestOptic(clean_settings(), SIZE, SIZE)
    times = np.arange(8) / (8 * frequency)  # one period, 8 equal samples
    applied = []
    for t in times:
        frame, truth = shaking.interferogram(float(t), 0.4)
        assert truth.phase_shift_rad == 0.4
        applied.append(truth.vibration_rad)
        np.testing.assert_array_equal(frame, still.interferogram(float(t), 0.4 + truth.vibration_rad)[0])
    # sqrt(2) rms sin(.) sampled evenly over a whole period has exactly that RMS
    assert math.isclose(float(np.sqrt(np.mean(np.square(applied)))), rms, rel_tol=1e-12)


def test_white_jitter_has_the_requested_rms() -> None:
    small = ApertureShape(centre_px=(8.0, 8.0), radius_px=6.0)
    optic = TestOptic(clean_settings(aperture=small, vibration_rms_rad=0.2), 16, 16)
    draws = np.array([optic.interferogram(0.0)[1].vibration_rad for _ in range(400)])
    # the sample RMS of n normals has relative standard error 1 / sqrt(2 n) = 3.5 %: allow 5 of them
    assert abs(np.sqrt(np.mean(draws**2)) / 0.2 - 1) < 5 / math.sqrt(800)


def test_frames_are_deterministic_and_noise_has_the_requested_rms() -> None:
    noisy = dict(aperture=CIRCLE, noise_rms=0.01, vibration_rms_rad=0.1, bit_depth=12, seed=5)
    first, second = TestOptic(OpticSettings(**noisy), SIZE, SIZE), TestOptic(OpticSettings(**noisy), SIZE, SIZE)
    other = TestOptic(OpticSettings(**{**noisy, "seed": 6}), SIZE, SIZE)
    for t in (0.0, 0.1, 0.2):
        a, truth_a = first.interferogram(t, 1.0)
        b, truth_b = second.interferogram(t, 1.0)
        np.testing.assert_array_equal(a, b)
        assert truth_a.vibration_rad == truth_b.vibration_rad
        assert np.any(a != other.interferogram(t, 1.0)[0])
    # outside the aperture the frame is the halo plus noise: its spread is the noise and rounding
    halo = a[~truth_a.mask].astype(np.float64)
    scale = 4095
    assert abs(halo.mean() - 0.03 * scale) < 0.5
    expected = math.sqrt((0.01 * scale) ** 2 + 1 / 12)  # Gaussian noise plus uniform rounding error
    # tens of thousands of samples: the sample std is within 2 % (many standard errors)
    assert abs(halo.std() / expected - 1) < 0.02


@pytest.mark.parametrize("bits, dtype", [(8, np.uint8), (12, np.uint16), (16, np.uint16)])
def test_bit_depth_and_clipping(bits: int, dtype: type) -> None:
    small = ApertureShape(centre_px=(32.0, 31.5), radius_px=28.0)
    optic = TestOptic(clean_settings(aperture=small, bit_depth=bits, background=0.8, modulation=0.5), 64, 64)
    frame, truth = optic.interferogram(0.0)
    assert frame.dtype == dtype
    full = (1 << bits) - 1
    # I = 0.8 + 0.5 cos(...) exceeds full scale where cos > 0.4: clipped there, never wrapped round
    phase = 2 * np.pi * truth.wavefront_waves[truth.mask]
    np.testing.assert_array_equal(frame[truth.mask][np.cos(phase) > 0.45], full)
    expected = np.rint(np.clip((0.8 + 0.5 * np.cos(phase)) * full, 0, full))
    assert np.max(np.abs(frame[truth.mask] - expected)) <= 1  # float32 rendering may round the other way


def test_aperture_change_mid_run() -> None:
    optic = TestOptic(clean_settings(), SIZE, SIZE)
    before = optic.interferogram(0.0)[1]
    optic.set_aperture(ANNULUS)
    frames, truth = four_frames(optic, 1.0)
    assert before.aperture_revision == 0 and truth.aperture_revision == 1 and optic.aperture == ANNULUS
    np.testing.assert_array_equal(truth.mask, ANNULUS.mask(SIZE, SIZE))
    assert truth.pupil_px == Aperture.from_mask(truth.mask).enclosing_circle()
    assert truth.pupil_px != before.pupil_px
    # outside the new aperture (the obscuration included) only the halo remains, in every frame
    halo = round(0.03 * 65535)
    assert np.all(frames[:, ~truth.mask] == halo)
    # the same coefficients on the new disk, measured through the annulus
    measured = measured_set(frames)
    fitter = build_fitter(measured.aperture, modes=len(COEFFICIENTS), dtype=np.float64, pupil=truth.pupil_px)
    error = fitter.fit(measured.waves, nan_policy="omit").coefficients - np.array(COEFFICIENTS)
    error[0] -= np.round(error[0])
    # the annulus conditions the circle basis worse than the disk: allow 10x the pixel bound
    assert np.max(np.abs(error)) < 10 * PIXEL_TOL_WAVES
    with pytest.raises(ValueError, match="ApertureShape"):
        optic.set_aperture("circle")  # type: ignore[arg-type]
