"""The machine frame of the pixel grid: x right, y up, origin at the grid centre, and back."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fuzz import fuzz_settings
from wavestack.pipeline.polishing.grid import GridFrame


def test_known_pixels_sit_where_the_contract_says() -> None:
    # 4 x 6 grid of 0.5 mm pixels: the centre is between rows 1 and 2 and columns 2 and 3
    frame = GridFrame((4, 6), pixel_mm=0.5)
    x, y = frame.to_mm([0, 3, 1], [0, 5, 3])
    # top-left pixel: left of and above the centre (2.5 columns, 1.5 rows away)
    assert (x[0], y[0]) == (-2.5 * 0.5, 1.5 * 0.5)
    # bottom-right pixel: right of and below it
    assert (x[1], y[1]) == (2.5 * 0.5, -1.5 * 0.5)
    # row 1, column 3: half a pixel right of and half a pixel above the centre
    assert (x[2], y[2]) == (0.25, 0.25)


def test_the_centre_pixel_of_an_odd_grid_is_the_origin() -> None:
    x, y = GridFrame((5, 7), pixel_mm=0.2).to_mm(2, 3)
    assert (float(x), float(y)) == (0.0, 0.0)


def test_one_column_right_is_plus_x_and_one_row_down_is_minus_y() -> None:
    frame = GridFrame((9, 9), pixel_mm=0.3)
    x0, y0 = frame.to_mm(4, 4)
    x_right, y_right = frame.to_mm(4, 5)
    x_down, y_down = frame.to_mm(5, 4)
    assert np.isclose(x_right - x0, 0.3) and y_right == y0
    assert np.isclose(y_down - y0, -0.3) and x_down == x0


@fuzz_settings(200)
@given(
    h=st.integers(1, 2048),
    w=st.integers(1, 2048),
    pixel_mm=st.floats(1e-3, 10.0),
    rows=hnp.arrays(np.float64, st.integers(0, 20), elements=st.floats(-100.0, 3000.0)),
    data=st.data(),
)
def test_to_px_inverts_to_mm(h: int, w: int, pixel_mm: float, rows: np.ndarray, data: st.DataObject) -> None:
    frame = GridFrame((h, w), pixel_mm)
    cols = data.draw(hnp.arrays(np.float64, rows.shape, elements=st.floats(-100.0, 3000.0)))
    x, y = frame.to_mm(rows, cols)
    back_rows, back_cols = frame.to_px(x, y)
    # two products and a division by pixel_mm: a few ulps of the largest magnitude involved
    tol = 1e-12 * (1.0 + max(h, w, float(np.max(np.abs(rows), initial=0)), float(np.max(np.abs(cols), initial=0))))
    np.testing.assert_allclose(back_rows, rows, rtol=0, atol=tol)
    np.testing.assert_allclose(back_cols, cols, rtol=0, atol=tol)


@pytest.mark.parametrize(
    ("shape", "pixel_mm", "message"),
    [
        ((0, 3), 1.0, "shape"),
        ((3,), 1.0, "shape"),
        ((3, 3), 0.0, "pixel_mm"),
        ((3, 3), float("nan"), "pixel_mm"),
        ((3, 3), True, "pixel_mm"),
        ((2.5, 3), 1.0, "shape"),
    ],
)
def test_bad_frames_are_refused_by_name(shape: tuple, pixel_mm: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        GridFrame(shape, pixel_mm)
