"""Tests for wavestack.pipeline.polishing.tif: Gaussian and measured tool influence functions."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from wavestack.pipeline.polishing import ToolInfluence


def test_gaussian_is_half_its_peak_at_half_the_fwhm() -> None:
    # FWHM 3 mm on 0.25 mm pixels is 12 px: the kernel must be at half its peak 6 px out,
    # which holds only if sigma = FWHM / (2 sqrt(2 ln 2)).
    tif = ToolInfluence.gaussian(fwhm_mm=3.0, peak_rate_nm_s=4.0, pixel_mm=0.25)
    r = tif.radius_px
    assert tif.kernel_nm_per_s[r, r] == pytest.approx(4.0)
    assert tif.kernel_nm_per_s[r, r + 6] == pytest.approx(2.0, rel=1e-12)
    assert tif.kernel_nm_per_s[r - 6, r] == pytest.approx(2.0, rel=1e-12)
    sigma_px = 12 / (2 * math.sqrt(2 * math.log(2)))
    assert r == math.floor(3 * sigma_px)


def test_gaussian_footprint_is_a_disc_of_its_radius() -> None:
    tif = ToolInfluence.gaussian(fwhm_mm=2.0, peak_rate_nm_s=1.0, pixel_mm=0.1)
    r = tif.radius_px
    offsets = np.arange(-r, r + 1)
    rho = np.hypot(offsets[:, None], offsets[None, :])
    sigma_px = 20 / (2 * math.sqrt(2 * math.log(2)))
    assert np.array_equal(tif.footprint, rho <= 3 * sigma_px)
    assert not tif.footprint[0, 0]  # the square's corner is beyond the disc


def test_kernel_is_read_only() -> None:
    tif = ToolInfluence.gaussian(fwhm_mm=1.0, peak_rate_nm_s=1.0, pixel_mm=0.25)
    with pytest.raises(ValueError):
        tif.kernel_nm_per_s[0, 0] = 5.0


def test_odd_map_is_kept_centred_and_trimmed() -> None:
    rates = np.zeros((9, 9))
    rates[3:6, 3:6] = 1.0
    rates[4, 5] = 3.0  # asymmetric: the middle pixel stays the centre all the same
    tif = ToolInfluence.from_map(rates, pixel_mm=0.5)
    assert tif.kernel_nm_per_s.shape == (3, 3)
    assert np.array_equal(tif.kernel_nm_per_s, rates[3:6, 3:6])


def test_even_map_is_recentred_on_its_centroid() -> None:
    reference = ToolInfluence.gaussian(fwhm_mm=1.0, peak_rate_nm_s=2.0, pixel_mm=0.2)
    size = reference.kernel_nm_per_s.shape[0]
    even = np.zeros((20, 24))
    even[3 : 3 + size, 7 : 7 + size] = reference.kernel_nm_per_s  # off-centre in an even array
    tif = ToolInfluence.from_map(even, pixel_mm=0.2, peak_rate_nm_s=4.0)
    assert np.allclose(tif.kernel_nm_per_s, 2.0 * reference.kernel_nm_per_s)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"fwhm_mm": 0.0, "peak_rate_nm_s": 1.0, "pixel_mm": 0.1}, "fwhm_mm"),
        ({"fwhm_mm": -1.0, "peak_rate_nm_s": 1.0, "pixel_mm": 0.1}, "fwhm_mm"),
        ({"fwhm_mm": math.nan, "peak_rate_nm_s": 1.0, "pixel_mm": 0.1}, "fwhm_mm"),
        ({"fwhm_mm": 1.0, "peak_rate_nm_s": 0.0, "pixel_mm": 0.1}, "peak_rate_nm_s"),
        ({"fwhm_mm": 1.0, "peak_rate_nm_s": 1.0, "pixel_mm": 0.0}, "pixel_mm"),
        ({"fwhm_mm": 1.0, "peak_rate_nm_s": 1.0, "pixel_mm": 0.1, "truncate_sigma": 0.0}, "truncate_sigma"),
    ],
)
def test_gaussian_refuses_bad_parameters(kwargs: dict, named: str) -> None:
    with pytest.raises(ValueError, match=named):
        ToolInfluence.gaussian(**kwargs)


@pytest.mark.parametrize(
    ("array", "message"),
    [
        (np.full((3, 3), np.nan), "finite"),
        (np.array([[0.0, -0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]), ">= 0"),
        (np.zeros((3, 3)), "all-zero"),
        (np.ones(5), "2-D"),
    ],
)
def test_from_map_refuses_bad_maps(array: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=f"array.*{message}|{message}.*array"):
        ToolInfluence.from_map(array, pixel_mm=0.1)


def test_constructor_refuses_an_even_kernel() -> None:
    with pytest.raises(ValueError, match="kernel_nm_per_s"):
        ToolInfluence(np.ones((4, 4)), pixel_mm=0.1)


def test_description_is_plain_json() -> None:
    gaussian = ToolInfluence.gaussian(fwhm_mm=2.0, peak_rate_nm_s=1.5, pixel_mm=0.25)
    described = json.loads(json.dumps(gaussian.as_dict()))
    assert described["kind"] == "gaussian" and described["fwhm_mm"] == 2.0
    assert described["radius_px"] == gaussian.radius_px
    # volume rate = kernel sum x pixel area; for a Gaussian close to 2 pi sigma^2 peak (98.9 %
    # of it within the 3-sigma cut, sampling adds well under 1 %)
    sigma_mm = 2.0 / (2 * math.sqrt(2 * math.log(2)))
    assert described["volume_rate_nm_mm2_s"] == pytest.approx(2 * math.pi * sigma_mm**2 * 1.5 * 0.989, rel=0.01)
    measured = ToolInfluence.from_map(gaussian.kernel_nm_per_s, pixel_mm=0.25).as_dict()
    assert measured["kind"] == "map" and len(measured["kernel_sha256"]) == 64
