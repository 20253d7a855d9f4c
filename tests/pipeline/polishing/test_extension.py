"""Tests for wavestack.pipeline.polishing.extension: the dwell grid and the smooth surface extension."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.polishing import ToolInfluence, dwell_grid, extend_surface, removal_nm


def _disc(shape: tuple[int, int], radius: float) -> np.ndarray:
    rows, cols = np.indices(shape) - (np.array(shape)[:, None, None] - 1) / 2
    return rows**2 + cols**2 < radius**2


def test_dwell_grid_holds_exactly_the_dwell_that_reaches_the_aperture() -> None:
    # A lopsided measured TIF: growing the aperture the wrong way round would fail this.
    rng = np.random.default_rng(4)
    rates = np.zeros((7, 7))
    rates[1:4, 2:7] = rng.random((3, 5)) + 0.1
    tif = ToolInfluence.from_map(rates, pixel_mm=0.1)
    aperture = np.zeros((30, 30), bool)
    aperture[10:16, 12:20] = True
    grid = dwell_grid(aperture, tif)
    assert np.all(grid[aperture])
    dwell = rng.random((30, 30))
    inside_only = np.where(grid, dwell, 0.0)
    # dwell outside the grid changes nothing in the aperture (round-off only) ...
    assert np.allclose(removal_nm(dwell, tif)[aperture], removal_nm(inside_only, tif)[aperture], atol=1e-12)
    # ... and every grid pixel outside the aperture does reach it
    for row, col in np.argwhere(grid & ~aperture):
        single = np.zeros((30, 30))
        single[row, col] = 1.0
        assert removal_nm(single, tif)[aperture].max() > 1e-12


def test_dwell_grid_grows_a_disc_by_the_tif_radius() -> None:
    tif = ToolInfluence.gaussian(fwhm_mm=1.5, peak_rate_nm_s=1.0, pixel_mm=0.25)
    aperture = _disc((64, 64), 15)
    grid = dwell_grid(aperture, tif)
    reach = 3 * 6 / (2 * np.sqrt(2 * np.log(2)))  # the 3-sigma cut of a 6 px FWHM, in px
    # on the pixel lattice the grown edge is exact to within a pixel either way
    assert np.all(grid[_disc((64, 64), 15 + reach - 1)])
    assert not np.any(grid[~_disc((64, 64), 15 + reach + 1)])


def test_extension_continues_a_low_order_surface_exactly() -> None:
    # A cubic is its own trend: the fit leaves no detail to fade, so the extension is the cubic.
    shape = (48, 48)
    aperture = _disc(shape, 14)
    rows, cols = np.indices(shape) - 23.5
    cubic = 3.0 + 0.2 * cols - 0.1 * rows + 0.01 * cols * rows + 0.002 * cols**3
    region = _disc(shape, 22)
    extended = extend_surface(np.where(aperture, cubic, np.nan), aperture, region)
    assert np.allclose(extended[region], cubic[region], atol=1e-8)
    assert np.all(np.isnan(extended[~region]))


def test_extension_keeps_the_aperture_and_is_continuous_at_the_edge() -> None:
    shape = (64, 64)
    aperture = _disc(shape, 20)
    rng = np.random.default_rng(5)
    surface = np.where(aperture, rng.normal(size=shape), np.nan)  # rough: worst case for a step
    region = _disc(shape, 28)
    extended = extend_surface(surface, aperture, region)
    assert np.array_equal(extended[aperture], surface[aperture])
    assert np.all(np.isfinite(extended[region]))
    # across the edge, neighbours differ no more than neighbours inside do (a step would)
    edge_pairs = aperture[:, :-1] ^ aperture[:, 1:]
    jumps = np.abs(np.diff(extended, axis=1))
    inside_pairs = aperture[:, :-1] & aperture[:, 1:]
    assert np.nanmean(jumps[edge_pairs]) <= 1.2 * np.nanmean(jumps[inside_pairs])


def test_extension_fades_the_detail_to_the_trend() -> None:
    shape = (80, 80)
    aperture = _disc(shape, 15)
    rng = np.random.default_rng(6)
    surface = np.where(aperture, rng.normal(size=shape), np.nan)
    extended = extend_surface(surface, aperture, np.ones(shape, bool), degree=0, decay_px=3.0)
    # degree 0: the trend is the mean; 25 px out the detail is down by exp(-25^2/18) ~ 1e-15
    corner = extended[:4, :4]
    assert np.allclose(corner, np.mean(surface[aperture]), atol=1e-9)


@pytest.mark.parametrize(
    ("change", "named"),
    [("shape", "clear_aperture"), ("nan", "surface_nm"), ("empty", "clear_aperture"), ("region", "region"),
     ("degree", "degree"), ("decay", "decay_px")],
)
def test_extension_refuses_bad_inputs(change: str, named: str) -> None:
    surface, aperture, region = np.zeros((10, 10)), _disc((10, 10), 3), np.ones((10, 10), bool)
    kwargs: dict = {}
    if change == "shape":
        aperture = _disc((10, 11), 3)
    elif change == "nan":
        surface[5, 5] = np.nan
    elif change == "empty":
        aperture = np.zeros((10, 10), bool)
    elif change == "region":
        region = np.ones((10, 10))
    elif change == "degree":
        kwargs["degree"] = -1
    else:
        kwargs["decay_px"] = 0.0
    with pytest.raises(ValueError, match=named):
        extend_surface(surface, aperture, region, **kwargs)


def test_dwell_grid_refuses_an_empty_aperture() -> None:
    tif = ToolInfluence.gaussian(fwhm_mm=1.0, peak_rate_nm_s=1.0, pixel_mm=0.25)
    with pytest.raises(ValueError, match="clear_aperture"):
        dwell_grid(np.zeros((10, 10), bool), tif)
