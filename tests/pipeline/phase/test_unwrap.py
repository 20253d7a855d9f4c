"""Tests for wavestack.pipeline.phase.spatial_unwrap: spatial (OpenCV histogram) and temporal unwrapping.

Accuracy criterion. The output is congruent modulo 2 pi to the input by construction
(float64 to rounding), so the only way to be wrong is a wrong multiple of 2 pi at some
pixels. After removing the single constant 2 pi k that unwrapping cannot determine, an RMS
error below 0.05 rad therefore allows at most (0.05 / 2 pi)^2 = 6e-5 of the pixels (about 3
of the ~45 000 pupil pixels used here) to be off by 2 pi; a correct unwrap measures ~1e-15.
Against the noise-free truth, a noisy map also carries its noise, so the noisy tests compare
with the noisy phase that was wrapped.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray
from wavestack.pipeline.phase import spatial_unwrap as unwrap_module
from wavestack.pipeline.aperture.region import EmptyAperture
from wavestack.pipeline.phase.spatial_unwrap import SpatialParams, count_residues, unwrap_spatial, wrap_phase
from wavestack.pipeline.phase.temporal_unwrap import TemporalUnwrapper, UnwrapResult

TWO_PI = 2.0 * math.pi
RMS_TOL = 0.05  # rad; see the module docstring
N = 256  # map size of most tests (OpenCV takes ~20 ms on a smooth 256 x 256 map)


# ----------------------------------------------------------------------------- helpers


def _pupil(
    shape: tuple[int, int] = (N, N), obscuration: float = 0.25
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Annular pupil (disk with a central obscuration) and normalised x, y (1 at the rim)."""
    rows, cols = shape
    radius = 0.45 * min(rows, cols)
    r_idx, c_idx = np.mgrid[:rows, :cols].astype(np.float64)
    x = (c_idx - (cols - 1) / 2) / radius
    y = -(r_idx - (rows - 1) / 2) / radius
    rho2 = x * x + y * y
    return (rho2 <= 1.0) & (rho2 >= obscuration**2), x, y


def _phase(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    tilt_x: float = 20.0,
    tilt_y: float = -8.0,
    defocus: float = 15.0,
) -> NDArray[np.float64]:
    """Tilt + defocus in radians: tens of radians peak to valley over the pupil."""
    return tilt_x * x + tilt_y * y + defocus * (2.0 * (x * x + y * y) - 1.0)


def _offset_turns(
    result: NDArray[np.float64], truth: NDArray[np.float64], mask: NDArray[np.bool_]
) -> int:
    """The constant multiple of 2 pi between result and truth (median over the mask)."""
    return int(np.rint(np.median((result - truth)[mask]) / TWO_PI))


def _error_rms(
    result: NDArray[np.float64], truth: NDArray[np.float64], mask: NDArray[np.bool_]
) -> float:
    """RMS of result - truth over the mask after removing the constant 2 pi k."""
    diff = (result - truth)[mask] - TWO_PI * _offset_turns(result, truth, mask)
    return float(np.sqrt(np.mean(diff**2)))


def _bump(
    mask_shape: tuple[int, int], row: float, col: float, sigma: float, height: float
) -> NDArray[np.float64]:
    """Smooth Gaussian bump of ``height`` rad centred on (row, col), width sigma px."""
    r_idx, c_idx = np.mgrid[: mask_shape[0], : mask_shape[1]].astype(np.float64)
    return height * np.exp(-((r_idx - row) ** 2 + (c_idx - col) ** 2) / (2.0 * sigma**2))


# ----------------------------------------------------------------------------- wrap_phase


@settings(max_examples=50, deadline=None)
@given(
    arrays(
        np.float64,
        st.integers(1, 40),
        elements=st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False),
    )
)
def test_wrap_phase_is_in_range_and_congruent(values: NDArray[np.float64]) -> None:
    wrapped = wrap_phase(values)
    assert wrapped.dtype == np.float64
    assert np.all(np.abs(wrapped) <= math.pi + 1e-12)
    turns = (values - wrapped) / TWO_PI
    np.testing.assert_allclose(turns, np.rint(turns), atol=1e-9)


def test_wrap_phase_keeps_nan_and_does_not_modify_input() -> None:
    values = np.array([np.nan, 7.0, -7.0])
    copy = values.copy()
    wrapped = wrap_phase(values)
    assert np.isnan(wrapped[0])
    np.testing.assert_allclose(wrapped[1:], [7.0 - TWO_PI, -7.0 + TWO_PI])
    np.testing.assert_array_equal(values, copy)


@pytest.mark.parametrize("bad", [np.array([1j]), np.array([True]), np.array(["a"])])
def test_wrap_phase_refuses_non_real(bad: NDArray[Any]) -> None:
    with pytest.raises(ValueError, match="phase must be real numeric"):
        wrap_phase(bad)


# ----------------------------------------------------------------------------- spatial


def test_spatial_recovers_tilt_and_defocus_on_obscured_disk() -> None:
    mask, x, y = _pupil()
    truth = _phase(x, y)
    assert np.ptp(truth[mask]) > 40.0  # tens of radians: many fringes
    result = unwrap_spatial(wrap_phase(truth), mask)
    assert result.dtype == np.float64
    assert result.shape == mask.shape
    assert np.all(np.isnan(result[~mask]))
    assert np.all(np.isfinite(result[mask]))
    assert _error_rms(result, truth, mask) < RMS_TOL
    # Stronger than the criterion: float64-exact, no float32 rounding left.
    diff = (result - truth)[mask]
    assert np.ptp(diff) < 1e-9
    assert abs(diff[0] / TWO_PI - round(diff[0] / TWO_PI)) < 1e-9


def test_spatial_non_square_map_sets_width_and_height_right() -> None:
    mask, x, y = _pupil((150, 260))
    truth = _phase(x, y, tilt_x=25.0, tilt_y=6.0)
    result = unwrap_spatial(wrap_phase(truth), mask)
    assert _error_rms(result, truth, mask) < RMS_TOL


def test_spatial_mask_touching_the_image_border() -> None:
    _, x, y = _pupil((120, 140))
    truth = _phase(x, y)
    mask = np.ones(truth.shape, dtype=bool)
    result = unwrap_spatial(wrap_phase(truth), mask)
    assert _error_rms(result, truth, mask) < RMS_TOL


def test_spatial_accepts_uint8_mask_and_float32_wrapped_with_nan_outside() -> None:
    mask, x, y = _pupil()
    truth = _phase(x, y)
    wrapped = np.where(mask, wrap_phase(truth), np.nan).astype(np.float32)
    mask_u8 = np.where(mask, 255, 0).astype(np.uint8)
    result = unwrap_spatial(wrapped, mask_u8)
    # float32 input: congruent to the float32 values, so within float32 rounding of truth.
    diff = (result - truth)[mask] - TWO_PI * _offset_turns(result, truth, mask)
    assert np.max(np.abs(diff)) < 1e-5


def test_spatial_accepts_any_wrapping_range() -> None:
    mask, x, y = _pupil()
    truth = _phase(x, y)
    shifted = np.mod(truth, TWO_PI)  # [0, 2 pi) instead of [-pi, pi]
    assert _error_rms(unwrap_spatial(shifted, mask), truth, mask) < RMS_TOL


def test_spatial_offset_convention_median_in_minus_pi_pi() -> None:
    mask, x, y = _pupil()
    for piston in (0.0, 3.0, 40.0, -77.0):
        result = unwrap_spatial(wrap_phase(_phase(x, y) + piston), mask)
        median = float(np.median(result[mask]))
        assert -math.pi <= median < math.pi


def test_spatial_offset_convention_holds_per_component() -> None:
    _, x, y = _pupil((120, 200))
    truth = _phase(x, y) + 50.0
    mask = np.zeros(truth.shape, dtype=bool)
    mask[5:55, 5:195] = True
    mask[65:115, 5:195] = True  # second 4-connected component
    result = unwrap_spatial(wrap_phase(truth), mask)
    for rows in (slice(0, 60), slice(60, 120)):
        values = result[rows][mask[rows]]
        assert -math.pi <= float(np.median(values)) < math.pi
        reference = truth[rows][mask[rows]]
        turns = np.rint(np.median(values - reference) / TWO_PI)
        assert np.max(np.abs(values - reference - TWO_PI * turns)) < 1e-9


def test_spatial_with_noise_matches_the_noisy_phase() -> None:
    mask, x, y = _pupil()
    truth = _phase(x, y)
    rng = np.random.default_rng(7)
    noisy = truth + rng.normal(0.0, 0.25, truth.shape)
    result = unwrap_spatial(wrap_phase(noisy), mask)
    assert _error_rms(result, noisy, mask) < RMS_TOL
    # Against the noise-free truth the error is the noise itself, not a 2 pi error.
    assert _error_rms(result, truth, mask) == pytest.approx(0.25, rel=0.05)


def test_spatial_prefilter_handles_strong_noise() -> None:
    mask, x, y = _pupil()
    truth = _phase(x, y)
    rng = np.random.default_rng(3)
    noisy = truth + rng.normal(0.0, 0.6, truth.shape)
    result = unwrap_spatial(wrap_phase(noisy), mask, SpatialParams(prefilter_sigma_px=1.5))
    assert _error_rms(result, noisy, mask) < RMS_TOL
    # Still congruent to the raw (unsmoothed) input everywhere.
    turns = (result - noisy)[mask] / TWO_PI
    np.testing.assert_allclose(turns, np.rint(turns), atol=1e-9)


def test_fresh_unwrapper_per_call_two_different_maps_in_a_row() -> None:
    """Pin: successive calls on different maps are each correct (no state carried over)."""
    mask, x, y = _pupil()
    first = _phase(x, y, tilt_x=20.0, tilt_y=-8.0, defocus=15.0)
    second = _phase(x, y, tilt_x=-12.0, tilt_y=9.0, defocus=25.0)
    for truth in (first, second, first):
        assert _error_rms(unwrap_spatial(wrap_phase(truth), mask), truth, mask) < RMS_TOL


def test_each_call_builds_its_own_opencv_object(monkeypatch: pytest.MonkeyPatch) -> None:
    """Pin the design, independently of whether OpenCV still has the reuse bug."""
    built: list[Any] = []
    original = unwrap_module._create_unwrapper

    def spy(*args: Any, **kwargs: Any) -> Any:
        built.append(original(*args, **kwargs))
        return built[-1]

    monkeypatch.setattr(unwrap_module, "_create_unwrapper", spy)
    mask, x, y = _pupil((64, 64))
    unwrap_spatial(wrap_phase(_phase(x, y)), mask)
    unwrap_spatial(wrap_phase(_phase(x, y, defocus=-10.0)), mask)
    assert len(built) == 2
    assert built[0] is not built[1]


def test_opencv_object_reuse_is_wrong_but_unwrap_spatial_is_not() -> None:
    """Documents the OpenCV bug; skips if this OpenCV no longer has it."""
    mask, x, y = _pupil((128, 128))
    first = _phase(x, y, tilt_x=20.0, tilt_y=-8.0, defocus=15.0)
    second = _phase(x, y, tilt_x=-12.0, tilt_y=9.0, defocus=25.0)
    shadow = np.where(mask, 255, 0).astype(np.uint8)
    reused = unwrap_module._create_unwrapper(128, 128, SpatialParams())
    reused.unwrapPhaseMap(wrap_phase(first).astype(np.float32), shadowMask=shadow)
    raw = reused.unwrapPhaseMap(wrap_phase(second).astype(np.float32), shadowMask=shadow)
    reuse_error = _error_rms(np.asarray(raw, dtype=np.float64), second, mask)
    if reuse_error < RMS_TOL:
        pytest.skip(f"OpenCV {cv2.__version__} unwraps correctly with a reused object")
    assert reuse_error > 1.0  # measured ~18 rad with OpenCV 5.0.0
    unwrap_spatial(wrap_phase(first), mask)
    assert _error_rms(unwrap_spatial(wrap_phase(second), mask), second, mask) < RMS_TOL


# ----------------------------------------------------------------------------- OpenCV API


class _FakeParams:
    """Stands for the OpenCV Params structure: plain attributes, OpenCV's defaults."""

    def __init__(self) -> None:
        self.width, self.height = 800, 600
        self.histThresh, self.nbrOfSmallBins, self.nbrOfLargeBins = 29.6, 10, 5


def _fake_create(params: _FakeParams) -> SimpleNamespace:
    return SimpleNamespace(params=params)


def test_params_api_opencv5_layout() -> None:
    cv = SimpleNamespace(
        phase_unwrapping=SimpleNamespace(
            HistogramPhaseUnwrapping=SimpleNamespace(Params=_FakeParams, create=_fake_create)
        )
    )
    made = unwrap_module._create_unwrapper(
        30, 40, SpatialParams(hist_thresh=12.5, n_small_bins=7, n_large_bins=3), cv
    )
    p = made.params
    assert (p.width, p.height) == (40, 30)  # width = columns, height = rows
    assert (p.histThresh, p.nbrOfSmallBins, p.nbrOfLargeBins) == (12.5, 7, 3)


@pytest.mark.parametrize("top_level_params", [True, False])
def test_params_api_opencv4_layouts(top_level_params: bool) -> None:
    module = SimpleNamespace(HistogramPhaseUnwrapping_create=_fake_create)
    cv = SimpleNamespace(phase_unwrapping=module)
    if top_level_params:  # cv2.phase_unwrapping_HistogramPhaseUnwrapping_Params()
        cv.phase_unwrapping_HistogramPhaseUnwrapping_Params = _FakeParams
    else:  # cv2.phase_unwrapping.HistogramPhaseUnwrapping_Params()
        module.HistogramPhaseUnwrapping_Params = _FakeParams
    made = unwrap_module._create_unwrapper(5, 9, SpatialParams(), cv)
    assert (made.params.width, made.params.height) == (9, 5)
    assert made.params.histThresh == pytest.approx(3.0 * math.pi**2)


def test_params_api_missing_module_raises_runtime_error() -> None:
    with pytest.raises(RuntimeError, match="opencv-contrib"):
        unwrap_module._create_unwrapper(5, 5, SpatialParams(), SimpleNamespace())


def test_params_api_real_opencv_builds_a_working_object() -> None:
    made = unwrap_module._create_unwrapper(8, 8, SpatialParams())
    assert hasattr(made, "unwrapPhaseMap")


# ----------------------------------------------------------------------------- residues


def test_count_residues_smooth_map_has_none() -> None:
    mask, x, y = _pupil()
    assert count_residues(wrap_phase(_phase(x, y)), mask) == 0


def test_count_residues_finds_vortices() -> None:
    rows, cols = np.mgrid[:40, :60].astype(np.float64)
    single = np.arctan2(rows - 20.5, cols - 20.5)  # one phase singularity between pixels
    mask = np.ones(single.shape, dtype=bool)
    assert count_residues(single, mask) == 1
    pair = single - np.arctan2(rows - 20.5, cols - 40.5)  # vortex and anti-vortex
    assert count_residues(pair, mask) == 2
    mask[15:26, 15:26] = False  # loops touching an invalid pixel do not count
    assert count_residues(pair, mask) == 1


# ----------------------------------------------------------------------------- temporal


def _stream(
    mask: NDArray[np.bool_], x: NDArray[np.float64], y: NDArray[np.float64], frames: int
) -> list[NDArray[np.float64]]:
    """True phases of a slowly drifting wavefront: < 0.5 rad change per frame."""
    return [
        _phase(x, y, tilt_x=20.0 + 0.2 * k, tilt_y=-8.0 - 0.1 * k, defocus=15.0 + 0.15 * k)
        + 0.3 * k
        for k in range(frames)
    ]


def test_temporal_follows_a_slow_drift() -> None:
    mask, x, y = _pupil()
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 12)
    offsets = []
    for k, truth in enumerate(truths):
        result = unwrapper.update(wrap_phase(truth), mask)
        assert isinstance(result, UnwrapResult)
        assert result.path == ("spatial" if k == 0 else "temporal"), result.reason
        assert result.residues == 0
        assert _error_rms(result.phase, truth, mask) < RMS_TOL
        assert np.all(np.isnan(result.phase[~mask]))
        offsets.append(_offset_turns(result.phase, truth, mask))
    assert len(set(offsets)) == 1  # the level stays continuous, no 2 pi jump


def test_temporal_result_is_read_only_and_independent_of_caller_arrays() -> None:
    mask, x, y = _pupil((64, 64))
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 3)
    first = unwrapper.update(wrap_phase(truths[0]), mask)
    with pytest.raises(ValueError):
        first.phase[0, 0] = 1.0
    caller_mask = mask.copy()
    second = unwrapper.update(wrap_phase(truths[1]), caller_mask)
    caller_mask[:] = False  # must not change the unwrapper's state
    third = unwrapper.update(wrap_phase(truths[2]), mask)
    assert second.path == third.path == "temporal"


def test_temporal_sudden_smooth_jump_larger_than_pi_falls_back_to_spatial() -> None:
    mask, x, y = _pupil()
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 6)
    bump = _bump(mask.shape, row=N / 2 - 70, col=N / 2, sigma=12.0, height=8.0)
    truths[3] = truths[3] + bump  # appears and vanishes within one frame each time
    offsets = []
    for k, truth in enumerate(truths):
        result = unwrapper.update(wrap_phase(truth), mask)
        if k in (3, 4):
            assert result.path == "spatial"
            assert "crossed +-pi" in result.reason
            assert result.residues == 0  # a smooth change: caught by the wrap-edge count
        elif k > 0:
            assert result.path == "temporal", result.reason
        assert _error_rms(result.phase, truth, mask) < RMS_TOL
        offsets.append(_offset_turns(result.phase, truth, mask))
    assert len(set(offsets)) == 1  # the fallback keeps the level continuous


def test_temporal_wrong_when_wrap_edge_check_is_disabled() -> None:
    """Why the check exists: the temporal formula alone gets a > pi change wrong."""
    mask, x, y = _pupil()
    unwrapper = TemporalUnwrapper(max_wrap_edges=10**9)
    truths = _stream(mask, x, y, 2)
    truths[1] = truths[1] + _bump(mask.shape, N / 2 - 70, N / 2, sigma=12.0, height=8.0)
    unwrapper.update(wrap_phase(truths[0]), mask)
    result = unwrapper.update(wrap_phase(truths[1]), mask)
    assert result.path == "temporal"
    assert _error_rms(result.phase, truths[1], mask) > 0.1


def test_temporal_discontinuous_jump_trips_the_residue_check() -> None:
    mask, x, y = _pupil()
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 3)
    jump = np.zeros(mask.shape)
    # A block of the pupil jumps by 1 to 6 rad (varying across it): a discontinuous change
    # whose height crosses pi inside the block, so its edges carry residues.
    jump[40:90, 100:160] = np.linspace(1.0, 6.0, 60)[np.newaxis, :]
    unwrapper.update(wrap_phase(truths[0]), mask)
    assert unwrapper.update(wrap_phase(truths[1]), mask).path == "temporal"
    result = unwrapper.update(wrap_phase(truths[2] + jump), mask)
    assert result.path == "spatial"
    assert result.residues > 0
    assert "residues in the frame difference" in result.reason


def test_temporal_tolerates_moderate_noise() -> None:
    mask, x, y = _pupil()
    unwrapper = TemporalUnwrapper()
    rng = np.random.default_rng(11)
    for k, truth in enumerate(_stream(mask, x, y, 8)):
        noisy = truth + rng.normal(0.0, 0.1, truth.shape)
        result = unwrapper.update(wrap_phase(noisy), mask)
        assert result.path == ("spatial" if k == 0 else "temporal"), result.reason
        assert _error_rms(result.phase, noisy, mask) < RMS_TOL


def test_temporal_mask_change_falls_back_to_spatial_and_keeps_level() -> None:
    mask, x, y = _pupil()
    smaller, _, _ = _pupil(obscuration=0.35)
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 4)
    offsets = []
    for k, (truth, m) in enumerate(zip(truths, (mask, mask, smaller, smaller), strict=True)):
        result = unwrapper.update(wrap_phase(truth), m)
        if k == 2:
            assert result.path == "spatial"
            assert result.reason.startswith("mask changed (IoU 0.9")
        elif k == 3:
            assert result.path == "temporal"
        assert _error_rms(result.phase, truth, m) < RMS_TOL
        assert np.all(np.isnan(result.phase[~m]))
        offsets.append(_offset_turns(result.phase, truth, m))
    assert len(set(offsets)) == 1


def test_temporal_single_pixel_mask_change_counts() -> None:
    mask, x, y = _pupil((64, 64))
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 2)
    unwrapper.update(wrap_phase(truths[0]), mask)
    changed = mask.copy()
    changed[np.argwhere(mask)[0][0], np.argwhere(mask)[0][1]] = False
    assert unwrapper.update(wrap_phase(truths[1]), changed).path == "spatial"


def test_temporal_reset_and_shape_change_fall_back_to_spatial() -> None:
    mask, x, y = _pupil((64, 64))
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 3)
    unwrapper.update(wrap_phase(truths[0]), mask)
    assert unwrapper.update(wrap_phase(truths[1]), mask).path == "temporal"
    unwrapper.reset()
    after_reset = unwrapper.update(wrap_phase(truths[2]), mask)
    assert after_reset.path == "spatial"
    assert after_reset.reason == "no previous frame"
    other_mask, ox, oy = _pupil((48, 80))
    resized = unwrapper.update(wrap_phase(_phase(ox, oy)), other_mask)
    assert resized.path == "spatial"
    assert "shape changed" in resized.reason


def test_temporal_matches_spatial_on_the_same_frame() -> None:
    mask, x, y = _pupil()
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 3)
    for truth in truths:
        result = unwrapper.update(wrap_phase(truth), mask)
    assert result.path == "temporal"
    spatial = unwrap_spatial(wrap_phase(truths[-1]), mask)
    diff = (result.phase - spatial)[mask]
    turns = np.rint(diff / TWO_PI)
    assert np.all(turns == turns[0])
    np.testing.assert_allclose(diff, TWO_PI * turns, atol=1e-9)


def test_temporal_limits_allow_small_defects() -> None:
    mask, x, y = _pupil()
    truths = _stream(mask, x, y, 2)
    jump = np.zeros(mask.shape)
    jump[40:90, 100:160] = np.linspace(1.0, 6.0, 60)[np.newaxis, :]
    strict, lenient = (
        TemporalUnwrapper(),
        TemporalUnwrapper(max_residues=10**6, max_wrap_edges=10**6),
    )
    for unwrapper in (strict, lenient):
        unwrapper.update(wrap_phase(truths[0]), mask)
    assert strict.update(wrap_phase(truths[1] + jump), mask).path == "spatial"
    lenient_result = lenient.update(wrap_phase(truths[1] + jump), mask)
    assert lenient_result.path == "temporal"
    assert lenient_result.residues > 0


# ----------------------------------------------------------------------------- bad input


def test_bad_input_shape_mismatch() -> None:
    mask, x, y = _pupil((32, 32))
    with pytest.raises(ValueError, match=r"mask must have the shape of wrapped \(32, 32\)"):
        unwrap_spatial(wrap_phase(_phase(x, y)), mask[:, :31])
    with pytest.raises(ValueError, match="mask must have the shape"):
        TemporalUnwrapper().update(wrap_phase(_phase(x, y)), mask[:31])


@pytest.mark.parametrize("shape", [(10,), (1, 10), (10, 1), (2, 3, 4)])
def test_bad_input_not_a_2d_map(shape: tuple[int, ...]) -> None:
    with pytest.raises(ValueError, match="wrapped must be a 2-D array"):
        unwrap_spatial(np.zeros(shape), np.ones(shape, dtype=bool))


def test_bad_input_empty_mask() -> None:
    mask, x, y = _pupil((32, 32))
    empty = np.zeros_like(mask)
    for call in (
        lambda: unwrap_spatial(wrap_phase(_phase(x, y)), empty),
        lambda: TemporalUnwrapper().update(wrap_phase(_phase(x, y)), empty),
        lambda: count_residues(wrap_phase(_phase(x, y)), empty),
    ):
        with pytest.raises(EmptyAperture, match="no valid"):
            call()
    assert issubclass(EmptyAperture, ValueError)


@pytest.mark.parametrize("bad_value", [np.nan, np.inf, -np.inf])
def test_bad_input_non_finite_inside_mask(bad_value: float) -> None:
    mask, x, y = _pupil((32, 32))
    wrapped = wrap_phase(_phase(x, y))
    row, col = np.argwhere(mask)[5]
    wrapped[row, col] = bad_value
    with pytest.raises(ValueError, match="wrapped must be finite inside the mask; 1 valid"):
        unwrap_spatial(wrapped, mask)
    with pytest.raises(ValueError, match="finite inside the mask"):
        TemporalUnwrapper().update(wrapped, mask)


def test_non_finite_outside_mask_is_fine() -> None:
    mask, x, y = _pupil((64, 64))
    truth = _phase(x, y)
    wrapped = np.where(mask, wrap_phase(truth), np.inf)
    assert _error_rms(unwrap_spatial(wrapped, mask), truth, mask) < RMS_TOL


@pytest.mark.parametrize(
    ("wrapped", "mask", "message"),
    [
        (np.zeros((8, 8), dtype=complex), np.ones((8, 8)), "wrapped must be real numeric"),
        (np.zeros((8, 8), dtype=bool), np.ones((8, 8)), "wrapped must be real numeric"),
        (np.zeros((8, 8)), np.full((8, 8), "x"), "mask must be boolean or real numeric"),
        (np.zeros((8, 8)), np.full((8, 8), np.nan), "mask must be finite"),
    ],
)
def test_bad_input_types(wrapped: NDArray[Any], mask: NDArray[Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        unwrap_spatial(wrapped, mask)


def test_bad_input_leaves_temporal_state_unchanged() -> None:
    mask, x, y = _pupil((64, 64))
    unwrapper = TemporalUnwrapper()
    truths = _stream(mask, x, y, 2)
    unwrapper.update(wrap_phase(truths[0]), mask)
    bad = wrap_phase(truths[1])
    bad[mask] = np.nan
    with pytest.raises(ValueError):
        unwrapper.update(bad, mask)
    assert unwrapper.update(wrap_phase(truths[1]), mask).path == "temporal"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_residues": -1}, "max_residues must be an integer >= 0"),
        ({"max_residues": 1.5}, "max_residues must be an integer >= 0"),
        ({"max_wrap_edges": True}, "max_wrap_edges must be an integer >= 0"),
        ({"params": {"hist_thresh": 1.0}}, "params must be a SpatialParams"),
    ],
)
def test_bad_temporal_settings(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TemporalUnwrapper(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"hist_thresh": 0.0}, "hist_thresh must be a real number in"),
        ({"hist_thresh": 32.0 * math.pi**2}, "hist_thresh must be a real number in"),
        ({"hist_thresh": math.nan}, "hist_thresh must be a real number in"),
        ({"n_small_bins": 0}, "n_small_bins must be an integer >= 1"),
        ({"n_large_bins": 2.0}, "n_large_bins must be an integer >= 1"),
        ({"prefilter_sigma_px": -1.0}, "prefilter_sigma_px must be a finite number >= 0"),
        ({"prefilter_sigma_px": math.inf}, "prefilter_sigma_px must be a finite number >= 0"),
    ],
)
def test_bad_spatial_params(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SpatialParams(**kwargs)
