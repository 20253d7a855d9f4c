"""Tests for wavestack.pipeline.polishing.removal: removal = TIF convolved with dwell; the residual."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.polishing import ToolInfluence, removal_nm, residual_after


def _asymmetric_tif() -> ToolInfluence:
    """A lopsided measured TIF: a flipped (correlation) or shifted kernel would show."""
    rng = np.random.default_rng(7)
    return ToolInfluence.from_map(rng.random((5, 5)), pixel_mm=0.1)


def test_removal_is_the_linear_convolution_summed_directly() -> None:
    tif = _asymmetric_tif()
    kernel, r = tif.kernel_nm_per_s, tif.radius_px
    rng = np.random.default_rng(1)
    dwell = rng.random((9, 11))
    expected = np.zeros_like(dwell)
    for row, col in np.ndindex(dwell.shape):  # removal[p] = sum_q dwell[q] kernel[p - q + r]
        for d_row in range(-r, r + 1):
            for d_col in range(-r, r + 1):
                target = (row + d_row, col + d_col)
                if 0 <= target[0] < dwell.shape[0] and 0 <= target[1] < dwell.shape[1]:
                    expected[target] += dwell[row, col] * kernel[d_row + r, d_col + r]
    # fftconvolve round-off: ~1e-15 relative per term, 25 terms of order 1
    assert np.allclose(removal_nm(dwell, tif), expected, rtol=0, atol=1e-12)


def test_one_second_at_one_pixel_leaves_the_kernel_there() -> None:
    tif = _asymmetric_tif()
    dwell = np.zeros((15, 15))
    dwell[6, 8] = 1.0
    removed = removal_nm(dwell, tif)
    assert np.allclose(removed[4:9, 6:11], tif.kernel_nm_per_s, atol=1e-12)
    removed[4:9, 6:11] = 0.0
    assert np.allclose(removed, 0.0, atol=1e-12)


def test_removal_refuses_nan_dwell() -> None:
    dwell = np.zeros((8, 8))
    dwell[2, 2] = np.nan
    with pytest.raises(ValueError, match="dwell_s"):
        removal_nm(dwell, _asymmetric_tif())


def test_residual_removes_piston_and_is_nan_outside() -> None:
    rng = np.random.default_rng(2)
    surface = rng.normal(size=(12, 12))
    aperture = np.zeros((12, 12), bool)
    aperture[2:10, 3:9] = True
    removal = rng.normal(size=(12, 12))
    residual, rms, pv = residual_after(surface, aperture, removal)
    shifted, rms_shifted, _ = residual_after(surface + 40.0, aperture, removal)  # a uniform layer
    assert np.allclose(residual[aperture], shifted[aperture]) and rms == pytest.approx(rms_shifted)
    left = surface[aperture] - removal[aperture]
    assert rms == pytest.approx(np.std(left))
    assert pv == pytest.approx(np.ptp(left))
    assert np.all(np.isnan(residual[~aperture]))
    assert residual[aperture].mean() == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ("surface_shape", "clear_aperture"),
        ("removal_shape", "removal"),
        ("surface_nan", "surface_nm"),
        ("removal_nan", "removal"),
        ("empty", "clear_aperture"),
    ],
)
def test_residual_refuses_bad_inputs(change: str, named: str) -> None:
    surface, removal = np.zeros((6, 6)), np.zeros((6, 6))
    aperture = np.ones((6, 6), bool)
    if change == "surface_shape":
        surface = np.zeros((6, 7))
    elif change == "removal_shape":
        removal = np.zeros((5, 6))
    elif change == "surface_nan":
        surface[3, 3] = np.nan
    elif change == "removal_nan":
        removal[3, 3] = np.nan
    else:
        aperture[:] = False
    with pytest.raises(ValueError, match=named):
        residual_after(surface, aperture, removal)
