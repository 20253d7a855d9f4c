"""Tests for wavestack.pipeline.phase.psi.algorithms: phase-shifting algorithms, sign convention, real frames.

Synthetic frames follow the project model I_k = A + B cos(phi + delta_k) with a random smooth
phase over a disk (Zernike-like terms, tilt up to 20 rad peak-to-valley), a spatially varying
background and modulation, and optional Gaussian noise. Phase errors are wrapped differences;
methods that fix the phase absolutely (known steps) are compared without any offset removed,
the others after removing their mean (circular) offset.

Tolerances: noise-free fixed-step formulas are exact, so 1e-9 rad allows only rounding. With
noise sigma on modulation B, least squares over N frames has a phase noise of
sigma / (B sqrt(N / 2)) rad; bounds are 1.5x that figure. Real-data bounds come from the data
(recorded below) with margins for a different reader or JPEG decoder.
"""

from __future__ import annotations

import logging
import pickle

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from wavestack.pipeline.phase.psi.demodulation import PhaseResult
from wavestack.pipeline.phase.psi.estimated_steps import advanced_iterative_psi, pca_psi
from wavestack.pipeline.phase.psi.algorithms import (
    four_step,
    hariharan_five_step,
    least_squares_psi,
    phase_from_frames,
)

from shared_data import DATA

PSI = DATA / "psi-mirror-654nm"
SIZE = 128
UNKNOWN_STEPS = np.radians([0.0, 55.0, 130.0, 170.0, 250.0, 300.0])

# ----------------------------------------------------------------------------- helpers


def _pupil(size: int = SIZE) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Normalised x (= col) and y (= -row) over a centred disk of radius 0.45 size, and the disk."""
    rows, cols = np.mgrid[:size, :size].astype(np.float64)
    radius = 0.45 * size
    x = (cols - (size - 1) / 2) / radius
    y = -(rows - (size - 1) / 2) / radius
    return x, y, x * x + y * y <= 1.0


def _random_phase(rng: np.random.Generator, tilt_pv: float = 20.0) -> NDArray[np.float64]:
    """Tilt of ``tilt_pv`` rad PV over the disk in a random direction plus random low-order terms."""
    x, y, _ = _pupil()
    r2 = x * x + y * y
    angle = rng.uniform(0.0, 2.0 * np.pi)
    phase = 0.5 * tilt_pv * (np.cos(angle) * x + np.sin(angle) * y)
    for term in (2 * r2 - 1, x * x - y * y, 2 * x * y, (3 * r2 - 2) * x, (3 * r2 - 2) * y, 6 * r2 * r2 - 6 * r2 + 1):
        phase += rng.normal(0.0, 1.5) * term
    return phase


def _frames(
    phase: NDArray[np.float64], steps: NDArray[np.float64], rng: np.random.Generator, noise: float = 0.0,
) -> NDArray[np.float64]:
    x, y, _ = _pupil(phase.shape[0])
    background = 120.0 + 20.0 * x - 10.0 * y
    modulation = 60.0 * np.exp(-0.3 * (x * x + y * y))
    frames = np.stack([background + modulation * np.cos(phase + d) for d in steps])
    if noise:
        frames += rng.normal(0.0, noise, frames.shape)
    return frames


def _wrapped(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.angle(np.exp(1j * a))


def _error(result: PhaseResult, truth: NDArray[np.float64], *, remove_offset: bool) -> tuple[float, float]:
    """(RMS, max) of the wrapped phase error over the disk, radians."""
    _, _, disk = _pupil(truth.shape[0])
    difference = _wrapped(result.phase - truth)[disk]
    if remove_offset:
        difference = _wrapped(difference - np.angle(np.mean(np.exp(1j * difference))))
    return float(np.sqrt(np.mean(difference**2))), float(np.max(np.abs(difference)))


def _noise_rms(noise: float, count: int) -> float:
    """Expected least-squares phase noise for modulation about 55 over the disk."""
    return noise / (55.0 * np.sqrt(count / 2.0))


# ----------------------------------------------------------------------------- fixed-step formulas


def test_four_step_is_exact_and_returns_the_fringe_parameters() -> None:
    rng = np.random.default_rng(1)
    phase = _random_phase(rng)
    frames = _frames(phase, np.arange(4) * np.pi / 2, rng)
    result = four_step(frames)
    assert _error(result, phase, remove_offset=False)[1] < 1e-9
    x, y, _ = _pupil()
    np.testing.assert_allclose(result.background, 120.0 + 20.0 * x - 10.0 * y, rtol=1e-12)
    np.testing.assert_allclose(result.modulation, 60.0 * np.exp(-0.3 * (x * x + y * y)), rtol=1e-9)
    np.testing.assert_allclose(result.quality, result.modulation / result.background, rtol=1e-12)
    np.testing.assert_allclose(result.steps, np.arange(4) * np.pi / 2)
    assert result.method == "four" and result.iterations is None
    assert result.phase.dtype == np.float64 and result.phase.shape == (SIZE, SIZE)


def test_hariharan_is_exact() -> None:
    rng = np.random.default_rng(2)
    phase = _random_phase(rng)
    result = hariharan_five_step(_frames(phase, np.arange(5) * np.pi / 2, rng))
    assert _error(result, phase, remove_offset=False)[1] < 1e-9
    np.testing.assert_allclose(result.steps, np.arange(5) * np.pi / 2)


def test_least_squares_with_known_arbitrary_steps_is_exact() -> None:
    rng = np.random.default_rng(3)
    phase = _random_phase(rng)
    result = least_squares_psi(_frames(phase, UNKNOWN_STEPS, rng), UNKNOWN_STEPS)
    assert _error(result, phase, remove_offset=False)[1] < 1e-9
    np.testing.assert_allclose(result.steps, UNKNOWN_STEPS)


@settings(max_examples=25, deadline=None)
@given(
    increments=st.lists(st.floats(0.3, 2.5), min_size=2, max_size=7),
    offset=st.floats(-np.pi, np.pi),
    seed=st.integers(0, 2**16),
)
def test_least_squares_is_exact_for_any_well_spread_steps(increments: list[float], offset: float, seed: int) -> None:
    """Steps with increments of 0.3-2.5 rad (at least three distinct modulo 2 pi when they do not
    close a cycle) recover the phase of frame 0 to rounding, in both directions."""
    steps = offset + np.concatenate([[0.0], np.cumsum(increments)])
    design = np.column_stack([np.ones_like(steps), np.cos(steps), np.sin(steps)])
    singular = np.linalg.svd(design, compute_uv=False)
    if singular[-1] < 0.05 * singular[0]:  # nearly degenerate step sets are not "well spread"
        return
    rng = np.random.default_rng(seed)
    phase = _random_phase(rng)
    truth = phase + steps[0]
    frames = _frames(truth, steps - steps[0], rng)
    assert _error(least_squares_psi(frames, steps), truth, remove_offset=False)[1] < 1e-8
    reversed_frames = _frames(truth, -(steps - steps[0]), rng)
    cw = phase_from_frames(reversed_frames, "lsq", steps, direction="cw")
    assert _error(cw, truth, remove_offset=False)[1] < 1e-8


def test_least_squares_refers_the_phase_to_the_first_frame() -> None:
    """Steps given as -pi .. pi (Hariharan's centring) still return the phase of frame 0."""
    rng = np.random.default_rng(4)
    phase = _random_phase(rng)
    centred = (np.arange(5) - 2) * np.pi / 2
    result = least_squares_psi(_frames(phase + centred[0], centred - centred[0], rng), centred)
    assert _error(result, phase + centred[0], remove_offset=False)[1] < 1e-9
    np.testing.assert_allclose(result.steps, np.arange(5) * np.pi / 2)


def test_uint8_frames_give_the_phase_to_quantisation_noise() -> None:
    rng = np.random.default_rng(5)
    phase = _random_phase(rng)
    frames = np.clip(np.rint(_frames(phase, np.arange(4) * np.pi / 2, rng)), 0, 255).astype(np.uint8)
    rms, _ = _error(four_step(frames), phase, remove_offset=False)
    # rounding noise 1/sqrt(12) counts on B ~ 55: about 0.004 rad
    assert rms < 0.008


def test_a_sequence_of_frames_equals_the_stacked_array() -> None:
    rng = np.random.default_rng(6)
    frames = _frames(_random_phase(rng), np.arange(4) * np.pi / 2, rng)
    np.testing.assert_array_equal(four_step(list(frames)).phase, four_step(frames).phase)


def test_hariharan_tolerates_a_linear_step_miscalibration() -> None:
    """Error is second order in the step scale error for Hariharan, first order for nominal LSQ."""
    rng = np.random.default_rng(7)
    phase = _random_phase(rng)
    nominal = np.arange(5) * np.pi / 2
    errors = {}
    for scale in (0.025, 0.05):
        frames = _frames(phase, nominal * (1.0 + scale), rng)
        errors["hariharan", scale] = _error(hariharan_five_step(frames), phase, remove_offset=True)[0]
        errors["lsq", scale] = _error(least_squares_psi(frames, nominal), phase, remove_offset=True)[0]
    # measured RMS at 5 %: Hariharan 0.0011 rad, nominal LSQ 0.0054 rad (four-step on the first
    # four frames: 0.028 rad); at 2.5 %: 0.00027 and 0.0023 rad
    assert errors["hariharan", 0.05] < 0.3 * errors["lsq", 0.05]
    assert 3.0 < errors["hariharan", 0.05] / errors["hariharan", 0.025] < 5.0  # quadratic: 4x
    assert 1.5 < errors["lsq", 0.05] / errors["lsq", 0.025] < 2.5  # linear: 2x


# ----------------------------------------------------------------------------- fast path (integer / float32 frames)

_FIXED = {"four": (four_step, 4), "hariharan": (hariharan_five_step, 5)}


def _camera_frames(count: int, dtype: str, rng: np.random.Generator) -> NDArray:
    """Fringe frames at pi/2 steps in the range of ``dtype``, rounded as a camera would (float32 not rounded)."""
    phase = _random_phase(rng)
    frames = _frames(phase, np.arange(count) * np.pi / 2, rng, noise=1.0)  # about 40 .. 200
    if dtype == "float32":
        return frames.astype(np.float32)
    info = np.iinfo(dtype)
    if info.bits == 16:  # use the range of a 16-bit camera: about 10000 .. 51000 counts
        frames = frames * 256.0 - (32768.0 if info.min < 0 else 0.0)
    elif info.min < 0:
        frames = frames - 128.0
    return np.clip(np.rint(frames), info.min, info.max).astype(dtype)


@pytest.mark.parametrize("method", sorted(_FIXED))
@pytest.mark.parametrize("dtype", ["uint8", "int8", "uint16", "int16", "float32"])
@pytest.mark.parametrize("direction", ["ccw", "cw"])
def test_fast_path_matches_the_float64_formula(method: str, dtype: str, direction: str) -> None:
    """Frames of integers up to 16 bits or float32 take the float32 path; the same frames as
    float64 take the float64 path. Tolerances: float32 rounding of the output, 1.2e-7 relative
    (half an ulp), plus a few ulps of numpy's float32 atan2: phase 1e-6 rad (measured 3.5e-7),
    maps 1e-6 relative (measured 3.6e-7)."""
    rng = np.random.default_rng(30)
    frames = _camera_frames(_FIXED[method][1], dtype, rng)
    fast = phase_from_frames(frames, method, direction=direction)
    exact = phase_from_frames(frames.astype(np.float64), method, direction=direction)
    for name in ("phase", "modulation", "background", "quality"):
        assert getattr(fast, name).dtype == np.float32 and getattr(exact, name).dtype == np.float64, name
    assert np.max(np.abs(_wrapped(fast.phase - exact.phase))) < 1e-6
    scale = float(np.max(np.abs(exact.background)))
    np.testing.assert_allclose(fast.modulation, exact.modulation, rtol=1e-6, atol=1e-6 * scale)
    np.testing.assert_allclose(fast.background, exact.background, rtol=1e-6, atol=1e-6 * scale)
    np.testing.assert_allclose(fast.quality, exact.quality, atol=1e-6)
    np.testing.assert_array_equal(fast.steps, exact.steps)
    assert fast.method == exact.method == method and fast.iterations is None


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    dtype=st.sampled_from(["uint8", "uint16", "int16"]),
    method=st.sampled_from(sorted(_FIXED)),
)
def test_fast_path_holds_for_any_integer_frames(seed: int, dtype: str, method: str) -> None:
    """Arbitrary integers over the whole range of the dtype (no fringe model: the sums hit
    their extremes, C = 0, S = 0 and C = S = 0 occur) agree with the float64 formula and stay
    in (-pi, pi]. Tolerance as above: float32 rounding plus a few ulps of atan2."""
    rng = np.random.default_rng(seed)
    info = np.iinfo(dtype)
    count = _FIXED[method][1]
    frames = rng.integers(info.min, info.max, size=(count, 9, 11), endpoint=True, dtype=dtype)
    frames[:, 0, :3] = info.max  # C = S = 0 on some pixels
    frames[:, 1, 0] = info.min
    frames[:, 1, 1] = info.max // 2
    frames[0, 1, 1], frames[2, 1, 1] = info.min, info.max  # S = 0, C < 0 (phase +pi)
    fast = phase_from_frames(frames, method)
    exact = phase_from_frames(frames.astype(np.float64), method)
    assert np.all(fast.phase > -np.pi) and np.all(fast.phase <= np.pi)
    assert fast.phase[1, 1] == np.float32(np.pi) and exact.phase[1, 1] == np.pi
    assert np.all(fast.phase[0, :3] == 0.0) and np.all(fast.modulation[0, :3] == 0.0)
    assert np.max(np.abs(_wrapped(fast.phase - exact.phase))) < 1e-6
    scale = float(info.max - info.min)
    np.testing.assert_allclose(fast.modulation, exact.modulation, rtol=1e-6, atol=1e-6 * scale)


def test_fast_path_sends_minus_pi_to_plus_pi_for_float32_frames() -> None:
    """Float32 frames can give S = -0.0 (0.0 - 0.0 from -0.0 and +0.0), for which atan2 returns
    -pi on the negative C axis; the result must be +pi like every other path."""
    frames = np.zeros((4, 2, 2), dtype=np.float32)
    frames[0] = 10.0
    frames[2, 0] = 30.0  # C = (I0 - I2) / 2: -10 on row 0, +5 on row 1
    frames[3] = -0.0  # S = (I3 - I1) / 2 = (-0.0 - 0.0) / 2 = -0.0
    result = four_step(frames)
    assert np.all(result.phase[0] == np.float32(np.pi)) and np.all(result.phase[1] == 0.0)
    assert np.all(phase_from_frames(frames, "four", direction="cw").phase[0] == np.float32(np.pi))


def test_background_and_quality_come_from_the_frames_as_they_were_at_the_call() -> None:
    """The fast path computes background and quality on first access from a private copy of the
    frames: changing the caller's array afterwards (a reused camera buffer) changes nothing."""
    rng = np.random.default_rng(31)
    frames = _camera_frames(4, "uint8", rng)
    expected = four_step(frames.astype(np.float64))
    result = four_step(frames)
    frames[:] = 0
    # float32 rounding of sums of at most 4 x 255: exact background; quality to 1e-6
    np.testing.assert_array_equal(result.background, expected.background)
    np.testing.assert_allclose(result.quality, expected.quality, atol=1e-6)
    for array in (result.phase, result.modulation, result.background, result.quality, result.steps):
        with pytest.raises(ValueError):
            array[0] = 0.0


def test_a_fast_path_result_survives_pickling_with_its_maps() -> None:
    frames = _camera_frames(4, "uint16", np.random.default_rng(33))
    result = four_step(frames)
    copy = pickle.loads(pickle.dumps(result))
    for name in ("phase", "modulation", "background", "quality", "steps"):
        np.testing.assert_array_equal(getattr(copy, name), getattr(result, name))
    assert copy.method == "four"


def test_fast_path_rejects_non_finite_float32_frames() -> None:
    frames = _camera_frames(5, "float32", np.random.default_rng(32))
    frames[4, 7, 9] = np.inf
    with pytest.raises(ValueError, match="frames: expected finite"):
        hariharan_five_step(frames)
    frames[4, 7, 9] = np.nan
    with pytest.raises(ValueError, match="frames: expected finite"):
        phase_from_frames(frames, "hariharan", direction="cw")


# ----------------------------------------------------------------------------- estimated steps


@pytest.mark.parametrize("noise", [0.0, 2.0])
def test_aia_recovers_unknown_steps_and_phase(noise: float) -> None:
    rng = np.random.default_rng(8)
    phase = _random_phase(rng)
    result = advanced_iterative_psi(_frames(phase, UNKNOWN_STEPS, rng, noise))
    step_error = np.degrees(np.abs(result.steps - UNKNOWN_STEPS)).max()
    rms, _ = _error(result, phase, remove_offset=False)
    if noise == 0.0:
        assert step_error < 0.05  # stops when a step moves < 1e-4 rad per iteration
        assert rms < 0.002
    else:
        assert step_error < 1.0
        assert rms < 1.5 * _noise_rms(noise, 6) + np.radians(0.5)
    assert result.method == "aia" and 1 < result.iterations < 50


@pytest.mark.parametrize("noise", [0.0, 2.0])
def test_pca_recovers_unknown_steps_and_phase(noise: float) -> None:
    rng = np.random.default_rng(9)
    phase = _random_phase(rng)
    result = pca_psi(_frames(phase, UNKNOWN_STEPS, rng, noise))
    step_error = np.degrees(np.abs(result.steps - UNKNOWN_STEPS)).max()
    rms, _ = _error(result, phase, remove_offset=False)
    if noise == 0.0:
        assert step_error < 1e-6  # the ellipse fit is exact on noise-free data
        assert rms < 1e-6
    else:
        assert step_error < 1.0
        assert rms < 1.5 * _noise_rms(noise, 6) + np.radians(0.5)
    assert result.method == "pca" and result.iterations is None


def test_aia_and_pca_with_a_mask_and_a_miscalibrated_shifter() -> None:
    """Nominal 90 degree steps that are really 8 % long: both estimators find the real ones."""
    rng = np.random.default_rng(10)
    phase = _random_phase(rng)
    true = np.arange(5) * np.pi / 2 * 1.08
    frames = _frames(phase, true, rng, 1.0)
    _, _, disk = _pupil()
    for result in (
        advanced_iterative_psi(frames, np.arange(5) * np.pi / 2, mask=disk),
        pca_psi(frames, mask=disk),
    ):
        assert np.degrees(np.abs(result.steps - true)).max() < 1.0
        assert _error(result, phase, remove_offset=False)[0] < 0.03


def test_pca_with_four_equal_steps_uses_the_circle_assumption() -> None:
    rng = np.random.default_rng(11)
    phase = _random_phase(rng)
    result = pca_psi(_frames(phase, np.arange(4) * np.pi / 2, rng))
    np.testing.assert_allclose(result.steps, np.arange(4) * np.pi / 2, atol=1e-9)
    assert _error(result, phase, remove_offset=False)[1] < 1e-9


def test_aia_logs_when_it_does_not_converge(caplog: pytest.LogCaptureFixture) -> None:
    rng = np.random.default_rng(12)
    frames = _frames(_random_phase(rng), UNKNOWN_STEPS, rng)
    with caplog.at_level(logging.WARNING, logger="wavestack.pipeline.phase.psi.algorithms"):
        result = advanced_iterative_psi(frames, max_iterations=2)
    assert result.iterations == 2
    assert any("did not converge" in record.getMessage() for record in caplog.records)


@pytest.mark.parametrize("estimator", [advanced_iterative_psi, pca_psi])
def test_step_estimators_refuse_frames_without_phase_variation(estimator) -> None:
    rng = np.random.default_rng(13)
    flat_phase = np.full((SIZE, SIZE), 0.7)
    with pytest.raises(ValueError, match="frames"):
        estimator(_frames(flat_phase, UNKNOWN_STEPS, rng))


# ----------------------------------------------------------------------------- convention


def test_sign_convention_positive_tilt_increases_along_plus_x_and_plus_y() -> None:
    """delta_k = +k step (ccw) and phi = +x tilt: the phase grows with col; phi = +y: falls with row."""
    rng = np.random.default_rng(14)
    rows, cols = np.mgrid[:SIZE, :SIZE].astype(np.float64)
    for tilt, axis, expected in ((0.2 * cols, 1, 0.2), (0.2 * -rows, 0, -0.2)):
        for method in ("four", "lsq", "aia", "pca"):
            count = 4 if method == "four" else 6
            frames = _frames(tilt, np.arange(count) * 2 * np.pi / count, rng)
            phase = phase_from_frames(frames, method).phase
            line = phase[SIZE // 2, :] if axis == 1 else phase[:, SIZE // 2]
            slope = np.mean(np.diff(np.unwrap(line)))
            assert slope == pytest.approx(expected, abs=1e-3), method


@pytest.mark.parametrize("method", ["four", "hariharan", "lsq", "aia", "pca"])
def test_clockwise_frames_with_direction_cw_give_the_same_phase(method: str) -> None:
    rng = np.random.default_rng(15)
    phase = _random_phase(rng)
    steps = {"four": np.arange(4) * np.pi / 2, "hariharan": np.arange(5) * np.pi / 2}.get(method, UNKNOWN_STEPS)
    given = steps if method == "lsq" else None
    ccw = phase_from_frames(_frames(phase, steps, rng), method, given)
    cw = phase_from_frames(_frames(phase, -steps, rng), method, given, direction="cw")
    exact = method in ("four", "hariharan", "lsq", "pca")
    tolerance = 1e-6 if exact else 2e-3
    assert _error(cw, phase, remove_offset=False)[0] < tolerance
    assert _error(ccw, phase, remove_offset=False)[0] < tolerance
    np.testing.assert_allclose(cw.steps, -ccw.steps, atol=1e-9 if exact else 1e-3)
    assert np.all(np.diff(cw.steps) < 0) and np.all(np.diff(ccw.steps) > 0)
    # read the wrong way round, the same frames give the negated phase
    wrong = phase_from_frames(_frames(phase, steps, rng), method, given, direction="cw")
    assert _error(wrong, -phase, remove_offset=False)[0] < tolerance


def test_phase_lies_in_minus_pi_excluded_to_pi() -> None:
    # phase exactly pi on every pixel: S = 0, C < 0
    frames = np.stack([100.0 + 50.0 * np.cos(np.pi + k * np.pi / 2) * np.ones((8, 8)) for k in range(4)])
    for result in (four_step(frames), phase_from_frames(frames, "four", direction="cw")):
        assert np.all(result.phase == np.pi)
    rng = np.random.default_rng(16)
    result = four_step(_frames(_random_phase(rng), np.arange(4) * np.pi / 2, rng).astype(np.float32))
    assert np.all(result.phase > -np.pi) and np.all(result.phase <= np.pi)
    assert np.all((result.quality >= 0) & (result.quality <= 1))


def test_results_are_read_only() -> None:
    rng = np.random.default_rng(17)
    result = four_step(_frames(_random_phase(rng), np.arange(4) * np.pi / 2, rng))
    for array in (result.phase, result.modulation, result.background, result.quality, result.steps):
        with pytest.raises(ValueError):
            array[0] = 0.0


# ----------------------------------------------------------------------------- bad input


def _good(count: int = 4) -> NDArray[np.float64]:
    rng = np.random.default_rng(18)
    return _frames(_random_phase(rng), np.arange(count) * 2 * np.pi / count, rng)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: four_step(_good(5)), "frames: expected exactly 4"),
        (lambda: hariharan_five_step(_good(4)), "frames: expected exactly 5"),
        (lambda: least_squares_psi(_good(4)[:2], [0, 1]), "frames: expected at least 3"),
        (lambda: four_step(_good(4)[0]), "frames: expected an \\(N, rows, cols\\)"),
        (lambda: four_step([np.zeros((4, 4))] * 3 + [np.zeros((4, 5))]), "frames: expected frames of equal shape"),
        (lambda: four_step(_good(4).astype(complex)), "frames: expected real numbers"),
        (lambda: four_step(np.where(np.arange(SIZE) == 3, np.nan, _good(4))), "frames: expected finite"),
        (lambda: four_step("frames"), "frames"),
        (lambda: least_squares_psi(_good(4), [0, 1, 2]), "steps: expected 4 phase steps"),
        (lambda: least_squares_psi(_good(4), [0, 0, 2 * np.pi, 0]), "steps: expected at least three distinct"),
        (lambda: least_squares_psi(_good(4), [0, 1, np.inf, 2]), "steps: expected finite"),
        (lambda: phase_from_frames(_good(4), "fft"), "method: expected one of"),
        (lambda: phase_from_frames(_good(4), "four", direction="up"), "direction: expected 'ccw' or 'cw'"),
        (lambda: phase_from_frames(_good(4), "four", steps=[0, 1, 2, 3]), "steps: method 'four'"),
        (lambda: phase_from_frames(_good(4), "pca", steps=[0, 1, 2, 3]), "steps: method 'pca'"),
        (lambda: advanced_iterative_psi(_good(4), tolerance=0.0), "tolerance: expected a positive"),
        (lambda: advanced_iterative_psi(_good(4), max_iterations=0), "max_iterations: expected an integer"),
        (lambda: advanced_iterative_psi(_good(4), [0, 1]), "initial_steps: expected 4"),
        (lambda: advanced_iterative_psi(_good(4), mask=np.ones((3, 3), bool)), "mask: expected shape"),
        (lambda: pca_psi(_good(4), mask=np.ones((SIZE, SIZE))), "mask: expected a boolean"),
        (lambda: pca_psi(_good(4), mask=np.zeros((SIZE, SIZE), bool)), "mask: expected at least"),
        (lambda: pca_psi(_good(4), direction="clockwise"), "direction"),
    ],
)
def test_bad_input_raises_value_error_naming_the_argument(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()


# ----------------------------------------------------------------------------- real frames

# Mirror disk in the 800 x 600 frames, read off the modulation map: centre (row 300, col 395),
# radius about 280 px; the speckled halo lies outside it.
_CENTRE, _RADIUS = (300.0, 395.0), 280.0


def _real(numbers: range) -> NDArray[np.uint8]:
    frames = [cv2.imread(str(PSI / f"Image{n}.jpg"), cv2.IMREAD_GRAYSCALE) for n in numbers]
    assert all(frame is not None and frame.shape == (600, 800) for frame in frames)
    return np.stack(frames)


@pytest.mark.skipif(not PSI.is_dir(), reason="real PSI frames not available")
@pytest.mark.parametrize("first", [5, 11])
def test_real_six_frame_cycles_give_60_degree_steps_and_a_bright_disk(first: int) -> None:
    """Measured: Image5-10 steps 0, 65.5, 124.2, 185.1, 242.8, 303.1 deg (AIA; PCA within 0.2);
    Image11-16 steps 0, 59.3, 118.9, 182.1, 237.4, 300.0 deg. Modulation ~75 on the disk, ~10 in
    the halo."""
    frames = _real(range(first, first + 6))
    aia = advanced_iterative_psi(frames, np.radians(60.0 * np.arange(6)))
    pca = pca_psi(frames)
    for result in (aia, pca):
        increments = np.degrees(np.diff(result.steps))
        assert np.all(np.abs(increments - 60.0) < 10.0), increments  # shifter non-linearity ~ +-6 deg
        assert abs(np.degrees(result.steps[-1]) / 5 - 60.0) < 3.0  # mean step
    assert np.degrees(np.abs(aia.steps - pca.steps)).max() < 1.0  # two independent estimators agree
    rows, cols = np.mgrid[:600, :800]
    radius = np.hypot(rows - _CENTRE[0], cols - _CENTRE[1])
    disk = np.median(aia.modulation[radius < 0.7 * _RADIUS])
    halo = np.median(aia.modulation[(radius > 1.15 * _RADIUS) & (radius < 1.35 * _RADIUS)])
    assert disk > 4.0 * halo
    assert np.median(aia.quality[radius < 0.7 * _RADIUS]) > 0.3
    assert np.isfinite(aia.phase).all()


@pytest.mark.skipif(not PSI.is_dir(), reason="real PSI frames not available")
def test_real_cycles_agree_with_each_other_and_with_all_twelve_frames() -> None:
    """The two cycles measure the same mirror: their phases differ by a piston equal to how far
    frame 11 is past 360 degrees (measured: 1.7 deg; 12-frame AIA puts frame 11 at 361.6 deg),
    with 0.11 rad RMS of noise and drift on the disk."""
    first = advanced_iterative_psi(_real(range(5, 11)), np.radians(60.0 * np.arange(6)))
    second = advanced_iterative_psi(_real(range(11, 17)), np.radians(60.0 * np.arange(6)))
    both = advanced_iterative_psi(_real(range(5, 17)), np.radians(60.0 * np.arange(12)))
    rows, cols = np.mgrid[:600, :800]
    disk = np.hypot(rows - _CENTRE[0], cols - _CENTRE[1]) < 0.9 * _RADIUS
    difference = _wrapped(second.phase - first.phase)[disk]
    piston = np.angle(np.mean(np.exp(1j * difference)))
    assert np.sqrt(np.mean(_wrapped(difference - piston) ** 2)) < 0.2
    assert np.degrees(abs(_wrapped(piston - (both.steps[6] - 2 * np.pi)))) < 1.5
    assert np.degrees(np.abs(both.steps[:6] - first.steps)).max() < 1.0
