"""The map as the browser gets it: block means, the colour scale, the PNG's pixels and the outline."""

from __future__ import annotations

import math

import cv2
import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fuzz import fuzz_settings
from wavestack.web import COLOURS, LEFT_OUT_COLOUR, downsample, render_map


def _naive_block_means(values: np.ndarray, factor: int) -> np.ndarray:
    rows, cols = -(-values.shape[0] // factor), -(-values.shape[1] // factor)
    out = np.full((rows, cols), np.nan)
    for i in range(rows):
        for j in range(cols):
            block = values[i * factor:(i + 1) * factor, j * factor:(j + 1) * factor]
            finite = block[np.isfinite(block)]
            if finite.size * 2 >= block.size:
                out[i, j] = finite.mean()
    return out


@fuzz_settings(200)
@given(arrays(np.float64, st.tuples(st.integers(1, 17), st.integers(1, 17)),
              elements=st.one_of(st.just(np.nan), st.floats(-1e3, 1e3))),
       st.integers(1, 6))
def test_downsample_is_the_block_mean_of_blocks_at_least_half_inside(values: np.ndarray, factor: int) -> None:
    got, expected = downsample(values, factor), _naive_block_means(values, factor)
    assert got.shape == expected.shape
    assert np.array_equal(np.isnan(got), np.isnan(expected))
    np.testing.assert_allclose(got[~np.isnan(got)], expected[~np.isnan(expected)], rtol=1e-12, atol=1e-9)


def _decoded(image) -> tuple[np.ndarray, np.ndarray]:
    """(values read back through the colour scale, alpha) of a rendered map."""
    bgra = cv2.imdecode(np.frombuffer(image.png, np.uint8), cv2.IMREAD_UNCHANGED)
    lut = np.array([[int(c[k:k + 2], 16) for k in (5, 3, 1)] for c in COLOURS], dtype=np.float64)
    level = np.argmin(((bgra[..., None, :3].astype(np.float64) - lut) ** 2).sum(axis=-1), axis=-1)
    return image.vmin + level / 255.0 * (image.vmax - image.vmin), bgra[..., 3]


def test_the_png_shows_the_map_through_its_colour_scale() -> None:
    y, x = np.mgrid[-1:1:300j, -1:1:240j]
    inside = x**2 + y**2 < 0.9
    values = np.where(inside, 0.4 * x - 0.25 * (2 * (x**2 + y**2) - 1), np.nan)
    image = render_map(values, units="waves", title="test", seq=3, max_side=100)
    assert (image.factor, image.width, image.height) == (3, 80, 100)  # ceil(300 / 100) = 3
    means = downsample(values, 3)
    shown, alpha = _decoded(image)
    assert np.array_equal(alpha > 0, np.isfinite(means))  # transparent exactly outside
    assert math.isclose(image.vmin, np.nanmin(means)) and math.isclose(image.vmax, np.nanmax(means))
    # one colour step is (vmax - vmin) / 255: rounding to the nearest level is half of it
    step = (image.vmax - image.vmin) / 255
    assert np.nanmax(np.abs(shown - means)[alpha > 0]) <= step / 2 + 1e-12
    finite = values[inside]
    assert math.isclose(image.rms, float(np.std(finite)), rel_tol=1e-9)
    assert math.isclose(image.pv, float(np.ptp(finite)), rel_tol=1e-9)
    assert image.colours[0] == COLOURS[0] and image.colours[-1] == COLOURS[-1] and image.units == "waves"


def test_the_outline_follows_the_aperture_and_its_hole() -> None:
    y, x = np.mgrid[0:200, 0:200]
    r = np.hypot(x - 100, y - 100)
    values = np.where((r < 80) & (r > 30), 1.0 + 0 * x, np.nan)
    image = render_map(values, units="waves", title="annulus", seq=1, max_side=100)
    radii = sorted(np.mean([math.hypot(px - 50, py - 50) for px, py in polygon]) for polygon in image.outline)
    assert len(radii) == 2  # the outer edge and the hole
    assert abs(radii[0] - 15) < 1.5 and abs(radii[1] - 40) < 1.5  # pixels of the PNG (factor 2)
    assert image.vmin == image.vmax == 1.0  # a flat map: one colour, no division by zero


def test_a_map_without_a_valid_pixel_is_an_empty_image() -> None:
    image = render_map(np.full((10, 10), np.nan), units="waves", title="none", seq=1)
    _, alpha = _decoded(image)
    assert not alpha.any() and image.outline == () and math.isnan(image.vmin) and math.isnan(image.rms)


def test_a_pixel_the_quality_mask_left_out_is_painted_as_left_out_never_as_a_value() -> None:
    # A ring of rim pixels clipped and a dropout inside: NaN in the map, flagged; the blocks holding
    # them are the left-out colour (not a colour of the scale), and every other block is its mean.
    y, x = np.mgrid[-1:1:120j, -1:1:120j]
    inside = x**2 + y**2 < 0.9
    flags = np.where(inside, 0, 128).astype(np.uint8)
    rim = inside & (x**2 + y**2 > 0.85) & (x > 0.3)  # part of the outermost ring, as spike clipping leaves it
    flags[rim] |= 8
    flags[60:63, 40:43] |= 1  # a dropout of low modulation
    values = np.where(inside & (flags == 0), 3.0 * (x**2 + y**2), np.nan)
    image = render_map(values, units="waves", title="test", seq=1, max_side=40, flags=flags)
    bgra = cv2.imdecode(np.frombuffer(image.png, np.uint8), cv2.IMREAD_UNCHANGED)
    painted = np.all(bgra[..., :3] == [int(LEFT_OUT_COLOUR[k:k + 2], 16) for k in (5, 3, 1)], axis=2)
    marked = downsample(((flags != 0) & (flags != 128)).astype(np.float64), image.factor) > 0
    assert image.left_out == int(rim.sum()) + 9
    assert np.array_equal(painted, marked) and (bgra[painted, 3] == 255).all()
    assert LEFT_OUT_COLOUR not in COLOURS
    shown, alpha = _decoded(image)
    means = downsample(values, image.factor)
    step = (image.vmax - image.vmin) / 255
    assert np.nanmax(np.abs(shown - means)[(alpha > 0) & ~painted]) <= step / 2 + 1e-12
