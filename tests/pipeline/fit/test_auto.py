"""The ``auto`` fit method, true conditioning messages whose advice works, and fitting a given set of
pixels (``fit_mask``)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from wavestack.pipeline.fit import (
    AUTO_MAX_NOISE_GAIN,
    MAX_GRAM_CONDITION,
    IllConditionedBasis,
    build_fitter,
    noise_gain,
)


def _strip() -> np.ndarray:
    """A long thin elliptical strip, 33 x 259 pixels: the shape of a real .datx strip."""
    rows, cols = np.mgrid[:33, :259]
    return ((rows - 16) / 16.5) ** 2 + ((cols - 129) / 129.5) ** 2 <= 1


def _disk(size: int = 120, radius: float = 55.0) -> np.ndarray:
    rows, cols = np.mgrid[:size, :size]
    return (rows - (size - 1) / 2) ** 2 + (cols - (size - 1) / 2) ** 2 < radius**2


def _circle_failure(mask: np.ndarray, method: str = "circle") -> IllConditionedBasis:
    with pytest.raises(IllConditionedBasis) as caught:
        build_fitter(mask, method=method, modes=36, dtype=np.float64)
    return caught.value


@pytest.mark.parametrize("method", ["circle", "qr"])
def test_the_printed_limit_is_the_one_compared(method: str) -> None:
    error = _circle_failure(_strip(), method)
    shown = re.search(r"kappa\(G\) = ([0-9.e+]+) .* above the limit ([0-9.e+]+)", str(error))
    assert shown, str(error)
    kappa, limit = float(shown.group(1)), float(shown.group(2))
    # the limit is printed exactly (2**52 = 1/eps) and the kappa shown is above it, as compared
    assert limit == MAX_GRAM_CONDITION == 2.0**52
    assert kappa > limit


@pytest.mark.parametrize("method", ["circle", "qr"])
def test_every_advised_setting_builds(method: str) -> None:
    error = _circle_failure(_strip(), method)
    assert ("method", "csf-qcm") in error.advice and "method 'csf-qcm'" in str(error)
    for setting, value in error.advice:
        settings = {"method": method, "modes": 36, setting: value}
        fitter = build_fitter(_strip(), dtype=np.float64, **settings)
        # what the advice promises: a fit whose coefficients are not swamped by noise
        assert fitter.diagnostics.noise_gain <= AUTO_MAX_NOISE_GAIN


def test_advised_mode_count_is_the_largest_well_conditioned_one() -> None:
    error = _circle_failure(_strip())
    usable = error.usable_modes
    assert usable is not None and 1 <= usable < 36
    # one mode more is not well conditioned (gain over the threshold, or the build fails)
    try:
        gain = build_fitter(_strip(), modes=usable + 1, dtype=np.float64).diagnostics.noise_gain
    except IllConditionedBasis:
        gain = np.inf
    assert gain > AUTO_MAX_NOISE_GAIN


def test_auto_maps_a_strip_and_says_why() -> None:
    fitter = build_fitter(_strip(), method="auto", modes=36, dtype=np.float64)
    assert fitter.basis.method == fitter.diagnostics.method == "csf-qcm"
    assert "circle basis is degenerate" in fitter.diagnostics.method_reason
    assert fitter.diagnostics.noise_gain <= AUTO_MAX_NOISE_GAIN


def test_auto_keeps_the_circle_basis_on_a_disk() -> None:
    mask = _disk()
    fitter = build_fitter(mask, method="auto", modes=36, dtype=np.float64)
    assert fitter.basis.method == "circle"
    # the gain quoted in the reason is the circle basis' own, recomputed here from its Gram matrix
    circle = build_fitter(mask, method="circle", modes=36, dtype=np.float64)
    assert f"noise gain {circle.diagnostics.noise_gain:.3g} <= 100" in fitter.diagnostics.method_reason


def test_auto_threshold_is_on_the_circle_noise_gain() -> None:
    """A 2:1 ellipse: the circle basis works (no error) but its gain is over the threshold."""
    rows, cols = np.mgrid[:100, :200]
    mask = ((rows - 49.5) / 47) ** 2 + ((cols - 99.5) / 95) ** 2 < 1
    circle = build_fitter(mask, method="circle", modes=36, dtype=np.float64)
    # the gain from the normalised Gram matrix of the unit-RMS circle columns, independently
    from wavestack.pipeline.zernike import mode_list, zernike_basis

    r, c = np.nonzero(mask)
    pupil = circle.basis.pupil
    columns = zernike_basis(mode_list("noll", 36), (c - pupil.cx) / pupil.radius,
                            (pupil.cy - r) / pupil.radius, normalisation="rms")
    gain = noise_gain(columns.T @ columns / r.size)
    assert gain == pytest.approx(circle.diagnostics.noise_gain, rel=1e-6)
    assert gain > AUTO_MAX_NOISE_GAIN
    assert build_fitter(mask, method="auto", modes=36, dtype=np.float64).basis.method == "csf-qcm"


def test_an_aperture_no_map_handles_gets_qr_from_auto() -> None:
    mask = np.zeros((33, 300), bool)
    mask[:, :140] = _strip()[:, :140]
    mask[:, 160:] = _strip()[:, 119:259]  # two pieces: no map; the circle basis is degenerate
    fitter = build_fitter(mask, method="auto", modes=21, dtype=np.float64)
    assert fitter.basis.method == "qr" and "cannot be mapped" in fitter.diagnostics.method_reason


def test_fit_mask_fits_exactly_those_pixels() -> None:
    outline = _disk()
    valid = outline.copy()
    valid[40, 40] = valid[70, 71] = False  # drop-outs
    valid[5, 60] = True  # an isolated pixel outside the outline
    fitter = build_fitter(outline, method="circle", modes=15, dtype=np.float64, fit_mask=valid)
    frame = np.where(valid, 1.0, np.nan)
    # no NaN among the fitted pixels: the default policy would raise on one
    result = fitter.fit(frame, residual=True)
    assert result.valid_count == int(valid.sum()) and result.nan_count == 0
    assert np.array_equal(np.isfinite(result.residual_map), valid)  # exactly those pixels


def test_fit_mask_of_another_shape_is_refused() -> None:
    with pytest.raises(ValueError, match="fit_mask: expected shape"):
        build_fitter(_disk(), fit_mask=np.ones((3, 3), bool))
