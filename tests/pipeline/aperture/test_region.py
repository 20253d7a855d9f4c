"""Tests for wavestack.pipeline.aperture.region: topology, boundary polygons, enclosing circle.

Conventions checked here: pixel centres at integer (row, col), physical x = col, y = -row;
outer polygons counter-clockwise and hole polygons clockwise in physical coordinates, offset
half a pixel outward from the centres of the boundary pixels.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.typing import NDArray
from scipy import ndimage

from wavestack.pipeline.aperture.region import Aperture, EmptyAperture, Topology, UnsupportedAperture

_EPS = 1e-9  # geometric tolerance of the test helpers, in pixels (vertices are k/4 px values)


# ----------------------------------------------------------------------------- helpers


def _disk(shape: tuple[int, int], row: float, col: float, radius: float) -> NDArray[np.bool_]:
    """Pixels whose centre lies within ``radius`` of (row, col)."""
    rows, cols = np.mgrid[: shape[0], : shape[1]]
    return (rows - row) ** 2 + (cols - col) ** 2 <= radius**2


def _shoelace(polygon: NDArray[np.float64]) -> float:
    """Signed area of a closed polygon (positive when counter-clockwise)."""
    x, y = polygon[:, 0], polygon[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _centres(mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Physical (x, y) = (col, -row) of the True pixels, shape (N, 2)."""
    rows, cols = np.nonzero(mask)
    return np.column_stack((cols, -rows)).astype(np.float64)


def _inside(polygon: NDArray[np.float64], points: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Even-odd ray casting (ray towards +x); points must not lie on the boundary."""
    x, y = points[:, :1], points[:, 1:]
    x1, y1 = polygon[None, :, 0], polygon[None, :, 1]
    x2, y2 = np.roll(polygon[:, 0], -1)[None], np.roll(polygon[:, 1], -1)[None]
    straddles = (y1 > y) != (y2 > y)
    x_cross = x1 + (y - y1) * (x2 - x1) / np.where(straddles, y2 - y1, 1.0)
    return np.count_nonzero(straddles & (x < x_cross), axis=1) % 2 == 1


def _region(aperture: Aperture) -> NDArray[np.bool_]:
    """Pixels whose centre is inside an odd number of the aperture's polygons."""
    rows, cols = np.mgrid[: aperture.shape[0], : aperture.shape[1]]
    points = np.column_stack((cols.ravel(), -rows.ravel())).astype(np.float64)
    inside = np.zeros(len(points), dtype=bool)
    for polygon in aperture.outers + aperture.holes:
        inside ^= _inside(polygon, points)
    return inside.reshape(aperture.shape)


def _orient(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Twice the signed area of triangles (a, b, c), broadcast over leading axes."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
        c[..., 0] - a[..., 0]
    )


def _on_segment(
    p: NDArray[np.float64], q: NDArray[np.float64], r: NDArray[np.float64], o: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """r lies on segment pq, given o = orient(p, q, r)."""
    return (
        (np.abs(o) <= _EPS)
        & (np.minimum(p[..., 0], q[..., 0]) - _EPS <= r[..., 0])
        & (r[..., 0] <= np.maximum(p[..., 0], q[..., 0]) + _EPS)
        & (np.minimum(p[..., 1], q[..., 1]) - _EPS <= r[..., 1])
        & (r[..., 1] <= np.maximum(p[..., 1], q[..., 1]) + _EPS)
    )


def _segments_meet(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64], d: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Segments ab and cd cross or touch (endpoint on the other segment, collinear overlap)."""
    o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
    proper = (o1 * o2 < -(_EPS**2)) & (o3 * o4 < -(_EPS**2))
    touch = _on_segment(a, b, c, o1) | _on_segment(a, b, d, o2)
    touch |= _on_segment(c, d, a, o3) | _on_segment(c, d, b, o4)
    return proper | touch


def _is_simple(polygon: NDArray[np.float64]) -> bool:
    """No two edges of the closed polygon meet except adjacent ones at their shared vertex."""
    k = len(polygon)
    start, end = polygon, np.roll(polygon, -1, axis=0)
    if k < 3 or np.any(np.hypot(*(end - start).T) <= _EPS):
        return False
    i, j = np.triu_indices(k, 1)
    adjacent = (j == i + 1) | ((i == 0) & (j == k - 1))
    far_i, far_j = i[~adjacent], j[~adjacent]
    if _segments_meet(start[far_i], end[far_i], start[far_j], end[far_j]).any():
        return False
    # Adjacent edges i -> i+1 share one vertex; the other end of one must not lie on the other
    # (that would be a zero-width spike folding back on itself).
    nxt = (np.arange(k) + 1) % k
    o = _orient(start, end, end[nxt])
    return not _on_segment(start, end, end[nxt], o).any()


def _disjoint(first: NDArray[np.float64], second: NDArray[np.float64]) -> bool:
    """No edge of one closed polygon meets an edge of the other."""
    a, b = first[:, None], np.roll(first, -1, axis=0)[:, None]
    c, d = second[None], np.roll(second, -1, axis=0)[None]
    return not _segments_meet(a, b, c, d).any()


def _butterfly(scale: float = 72.0, size: int = 221) -> NDArray[np.bool_]:
    """r(t) = scale (1 + 0.25 cos 2t - 0.38 cos 4t) about the image centre (~200 px wide)."""
    rows, cols = np.mgrid[:size, :size]
    x, y = cols - size // 2, size // 2 - rows
    t = np.arctan2(y, x)
    return np.hypot(x, y) <= scale * (1.0 + 0.25 * np.cos(2 * t) - 0.38 * np.cos(4 * t))


def _rounded_rectangle() -> NDArray[np.bool_]:
    """175 x 50 px rectangle (3.5:1) with 10 px corner radius, via its signed distance."""
    rows, cols = np.mgrid[:70, :195]
    half_w, half_h, radius = 87.5, 25.0, 10.0
    qx = np.abs(cols - 97) - (half_w - radius)
    qy = np.abs(rows - 35) - (half_h - radius)
    outside = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0))
    return outside + np.minimum(np.maximum(qx, qy), 0) - radius <= 0


# ----------------------------------------------------------------------- test helpers work


def test_helpers_detect_self_intersection_and_orientation() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    bow_tie = np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]])
    # Two squares sharing the corner (1, 1): touches itself without crossing.
    pinched = np.array(
        [[0, 0], [1, 0], [1, 1], [2, 1], [2, 2], [1, 2], [1, 1], [0, 1]], dtype=np.float64
    )
    spike = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    assert _is_simple(square)
    assert not _is_simple(bow_tie)
    assert not _is_simple(pinched)
    assert not _is_simple(spike)
    assert _shoelace(square) == 1.0 and _shoelace(square[::-1]) == -1.0
    assert not _disjoint(square, square + 0.5) and _disjoint(square, square + 2.0)
    inside = _inside(square, np.array([[0.5, 0.5], [1.5, 0.5], [-0.2, 0.9]]))
    assert inside.tolist() == [True, False, False]


# --------------------------------------------------------------------------------- shapes


def test_disk_is_simply_connected_with_a_ccw_outline_on_the_circle() -> None:
    radius, centre = 40.0, 50
    mask = _disk((101, 101), centre, centre, radius)
    aperture = Aperture.from_mask(mask)

    assert aperture.topology is Topology.SIMPLY_CONNECTED
    assert (aperture.components, len(aperture.outers), aperture.holes) == (1, 1, ())
    assert aperture.ignored_holes == 0
    outline = aperture.outer
    assert outline.dtype == np.float64 and outline.ndim == 2 and outline.shape[1] == 2
    area = _shoelace(outline)
    count = int(mask.sum())
    assert area > 0  # counter-clockwise in physical coordinates
    # Each boundary step adds half a pixel as in Pick's theorem; only the corners where a
    # diagonal step meets an axis step deviate (1/8 px^2 each), far below 1 % of the count.
    assert abs(area - count) <= 0.01 * count
    assert _inside(outline, _centres(mask)).all()
    assert _is_simple(outline)
    # Vertices lie in the pixel square of a boundary pixel whose centre is within 1 px inside
    # the circle, pushed 0.35-0.5 px outward: within 0.75 px of the circle of radius 40.
    distance = np.hypot(outline[:, 0] - centre, outline[:, 1] + centre)
    assert np.max(np.abs(distance - radius)) <= 0.75


@pytest.mark.parametrize(
    ("shape", "rows", "cols"),
    [
        ((40, 50), (10, 30), (5, 45)),  # 20 x 40 block inside the image
        ((12, 12), (3, 6), (4, 7)),  # 3 x 3 square
        ((9, 7), (0, 9), (0, 7)),  # the whole image, touching every border
        ((5, 5), (2, 3), (2, 3)),  # one pixel
    ],
)
def test_axis_aligned_rectangle_gives_the_pixel_region_exactly(
    shape: tuple[int, int], rows: tuple[int, int], cols: tuple[int, int]
) -> None:
    mask = np.zeros(shape, dtype=bool)
    mask[rows[0] : rows[1], cols[0] : cols[1]] = True
    aperture = Aperture.from_mask(mask)
    outline = aperture.outer

    # Pixel region: columns c0 .. c1-1 span x in [c0 - 0.5, c1 - 0.5]; rows r0 .. r1-1 span
    # y = -row in [-(r1 - 0.5), -(r0 - 0.5)].
    x_lo, x_hi = cols[0] - 0.5, cols[1] - 0.5
    y_lo, y_hi = -(rows[1] - 0.5), -(rows[0] - 0.5)
    x, y = outline[:, 0], outline[:, 1]
    on_vertical = (x == x_lo) | (x == x_hi)
    on_horizontal = (y == y_lo) | (y == y_hi)
    within = (x >= x_lo) & (x <= x_hi) & (y >= y_lo) & (y <= y_hi)
    assert np.all(within & (on_vertical | on_horizontal))
    corners = {(x_lo, y_lo), (x_hi, y_lo), (x_hi, y_hi), (x_lo, y_hi)}
    assert corners <= {tuple(v) for v in outline.tolist()}
    # Vertices on the rectangle's edges, all four corners, simple and the full area: the
    # polygon is the rectangle (exact: every coordinate is a multiple of 0.5).
    assert _shoelace(outline) == (rows[1] - rows[0]) * (cols[1] - cols[0])
    assert _is_simple(outline)


@pytest.mark.parametrize("hole_centre", [(50, 50), (45, 58)], ids=["centred", "eccentric"])
def test_annulus_is_doubly_connected_with_a_clockwise_hole(hole_centre: tuple[int, int]) -> None:
    disk = _disk((101, 101), 50, 50, 40.0)
    hole_pixels = disk & _disk((101, 101), *hole_centre, 15.0)
    mask = disk & ~hole_pixels
    aperture = Aperture.from_mask(mask)

    assert aperture.topology is Topology.DOUBLY_CONNECTED
    assert (aperture.components, len(aperture.holes), aperture.ignored_holes) == (1, 1, 0)
    hole = aperture.hole
    assert hole is not None and hole is aperture.holes[0]
    assert _shoelace(aperture.outer) > 0
    area = _shoelace(hole)
    assert area < 0  # clockwise in physical coordinates
    # Same Pick's-theorem argument as for the disk: within 1 % of the hole's pixel count.
    count = int(hole_pixels.sum())
    assert abs(-area - count) <= 0.01 * count
    assert _is_simple(hole) and _is_simple(aperture.outer) and _disjoint(hole, aperture.outer)
    assert _inside(hole, _centres(hole_pixels)).all()
    assert not _inside(hole, _centres(mask)).any()
    assert np.array_equal(_region(aperture), mask)


@pytest.mark.parametrize("stacked", [False, True], ids=["side by side", "stacked"])
def test_one_pixel_thin_walls_map_each_hole_to_its_own_area(stacked: bool) -> None:
    # A 1-px frame around two holes split by a 1-px wall: each hole contour touches the
    # outside background and the other hole, so the hole areas must not get mixed up.
    mask = np.zeros((8, 11), dtype=bool)
    mask[1:7, 1:10] = True
    mask[2:6, 2:4] = False  # hole of 4 x 2 = 8 px
    mask[2:6, 5:9] = False  # hole of 4 x 4 = 16 px
    if stacked:
        mask = np.ascontiguousarray(mask.T)
    both = Aperture.from_mask(mask, min_hole_area_px=8)
    assert (len(both.holes), both.ignored_holes) == (2, 0)
    # Holes are sorted by decreasing pixel count. The 8-connected border of a hole cuts each
    # of its 4 corners diagonally (the corner wall pixel only touches the hole diagonally),
    # which leaves out a right triangle with 0.5 px legs, 1/8 px^2: area = count - 4/8.
    assert [-_shoelace(h) for h in both.holes] == [16.0 - 0.5, 8.0 - 0.5]
    large_only = Aperture.from_mask(mask, min_hole_area_px=9)
    assert (len(large_only.holes), large_only.ignored_holes) == (1, 1)
    assert large_only.topology is Topology.DOUBLY_CONNECTED
    assert -_shoelace(large_only.holes[0]) == 16.0 - 0.5
    assert np.array_equal(_region(both), mask)


def _vertices_in_valid_pixel_squares(aperture: Aperture) -> bool:
    """Every polygon vertex lies in the closed unit square of some valid pixel."""
    vertices = np.concatenate(aperture.outers + aperture.holes)
    centres = _centres(aperture.mask)
    chebyshev = np.max(np.abs(vertices[:, None, :] - centres[None, :, :]), axis=2)
    return bool(np.all(np.min(chebyshev, axis=1) <= 0.5 + _EPS))


def test_sharp_turns_stay_in_the_pixel_squares_and_simple() -> None:
    # The border of this C shape turns by 135 degrees at the ends of the arms; an unbounded
    # miter there would reach 1.1 px out and make the outline cross itself.
    mask = np.array(
        [[1, 1, 1], [1, 0, 1], [0, 0, 1], [1, 0, 1], [1, 1, 1]], dtype=bool
    )
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.SIMPLY_CONNECTED
    assert _is_simple(aperture.outer)
    assert _vertices_in_valid_pixel_squares(aperture)
    assert np.array_equal(_region(aperture), mask)


def test_small_hole_is_ignored_below_the_threshold_and_counted_above() -> None:
    mask = _disk((41, 41), 20, 20, 15.0)
    mask[20, 20:22] = False  # a 2-px hole
    default = Aperture.from_mask(mask)  # min_hole_area_px = 4
    assert default.topology is Topology.SIMPLY_CONNECTED
    assert (default.holes, default.ignored_holes, default.min_hole_area_px) == ((), 1, 4.0)
    assert default.hole is None
    default.require_supported()

    counted = Aperture.from_mask(mask, min_hole_area_px=1)
    assert counted.topology is Topology.DOUBLY_CONNECTED
    assert (len(counted.holes), counted.ignored_holes) == (1, 0)
    assert _inside(counted.holes[0], np.array([[20.0, -20.0], [21.0, -20.0]])).all()

    # The threshold is inclusive: a 2 x 2 hole of exactly 4 px counts by default.
    mask[20:22, 20:22] = False
    assert Aperture.from_mask(mask).topology is Topology.DOUBLY_CONNECTED


def test_two_disks_are_unsupported() -> None:
    mask = _disk((41, 101), 20, 20, 10.0) | _disk((41, 101), 20, 80, 10.0)
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.UNSUPPORTED
    assert (aperture.components, len(aperture.outers)) == (2, 2)
    assert all(_shoelace(p) > 0 and _is_simple(p) for p in aperture.outers)
    with pytest.raises(UnsupportedAperture, match="2 components"):
        aperture.require_supported()
    with pytest.raises(UnsupportedAperture, match="2 components"):
        _ = aperture.outer
    assert np.array_equal(_region(aperture), mask)


def test_disk_with_two_holes_is_unsupported() -> None:
    mask = _disk((81, 81), 40, 40, 35.0)
    mask &= ~_disk((81, 81), 40, 22, 8.0) & ~_disk((81, 81), 40, 58, 8.0)
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.UNSUPPORTED
    assert (aperture.components, len(aperture.holes)) == (1, 2)
    with pytest.raises(UnsupportedAperture, match="1 component and 2 holes"):
        aperture.require_supported()
    with pytest.raises(UnsupportedAperture, match="2 holes"):
        _ = aperture.hole
    assert aperture.outer is aperture.outers[0]  # one component: the outline is available
    assert _disjoint(aperture.holes[0], aperture.holes[1])


def test_errors_are_value_errors() -> None:
    assert issubclass(UnsupportedAperture, ValueError)
    assert issubclass(EmptyAperture, ValueError)


def test_empty_mask_raises_empty_aperture() -> None:
    with pytest.raises(EmptyAperture, match="no valid"):
        Aperture.from_mask(np.zeros((10, 12)))


@pytest.mark.parametrize(
    ("mask", "named"),
    [
        (np.ones((3, 3, 3), dtype=bool), r"\(3, 3, 3\)"),
        (np.ones(5, dtype=bool), r"\(5,\)"),
        (np.zeros((0, 4), dtype=bool), r"\(0, 4\)"),
        (np.ones((4, 0)), r"\(4, 0\)"),
        (np.ones((3, 3), dtype=complex), "complex128"),
        (np.array([[None, 1], [1, 1]], dtype=object), "object"),
        (np.array([["a", "b"]]), "<U1"),
        (np.array([[1.0, np.nan], [1.0, 1.0]]), "NaN"),
        ([[1, 0], [1]], "could not convert"),
    ],
    ids=["3-D", "1-D", "no rows", "no cols", "complex", "object", "strings", "NaN", "ragged"],
)
def test_bad_mask_raises_value_error_naming_it(mask: object, named: str) -> None:
    with pytest.raises(ValueError, match=r"^mask") as info:
        Aperture.from_mask(mask)  # type: ignore[arg-type]
    assert not isinstance(info.value, EmptyAperture)
    assert info.match(named)


@pytest.mark.parametrize("value", [-1.0, float("nan"), float("inf"), "4", True, None])
def test_bad_min_hole_area_raises_value_error_naming_it(value: object) -> None:
    with pytest.raises(ValueError, match="min_hole_area_px"):
        Aperture.from_mask(np.ones((3, 3)), min_hole_area_px=value)  # type: ignore[arg-type]


def test_single_pixel_is_its_unit_square() -> None:
    mask = np.zeros((3, 4), dtype=bool)
    mask[0, 0] = True  # top-left corner of the image: the square reaches x, y = -0.5
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.SIMPLY_CONNECTED
    outline = aperture.outer
    expected = {(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)}
    assert len(outline) == 4 and {tuple(v) for v in outline.tolist()} == expected
    assert _shoelace(outline) == 1.0


@pytest.mark.parametrize("direction", ["horizontal", "vertical", "diagonal", "anti-diagonal"])
def test_one_pixel_wide_line_gives_a_simple_polygon_around_it(direction: str) -> None:
    mask = np.zeros((14, 14), dtype=bool)
    index = np.arange(2, 12)  # 10 pixels
    if direction == "horizontal":
        mask[5, index] = True
    elif direction == "vertical":
        mask[index, 5] = True
    elif direction == "diagonal":
        mask[index, index] = True
    else:
        mask[index, 13 - index] = True
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.SIMPLY_CONNECTED
    outline = aperture.outer
    assert _is_simple(outline)
    assert _shoelace(outline) > 0
    assert np.array_equal(_region(aperture), mask)
    area = _shoelace(outline)
    if direction in ("horizontal", "vertical"):
        assert area == 10.0  # exactly the 10 x 1 pixel region (multiples of 0.5 px)
    else:
        # A diagonal run is a band of width 1/sqrt(2) and length sqrt(2) per pixel (area 1)
        # with the two end caps clipped by 1/8 px^2 each: 10 - 1/4.
        assert area == pytest.approx(9.75, abs=1e-12)


def test_mask_touching_the_image_border() -> None:
    mask = _disk((60, 101), 0, 50, 40.0)  # centred on row 0: the image edge cuts it in half
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.SIMPLY_CONNECTED
    outline = aperture.outer
    assert np.max(outline[:, 1]) == 0.5  # top edge of row 0
    assert _is_simple(outline) and _inside(outline, _centres(mask)).all()
    count = int(mask.sum())
    assert abs(_shoelace(outline) - count) <= 0.01 * count  # as for the full disk


def test_physical_coordinates_put_row_zero_at_the_top() -> None:
    mask = np.zeros((50, 50), dtype=bool)
    mask[0:5, 10:40] = True  # the top five rows
    outline = Aperture.from_mask(mask).outer
    # Rows 0..4 -> y = 0 .. -4, edges at +0.5 and -4.5; columns 10..39 -> x edges 9.5, 39.5.
    assert (np.max(outline[:, 1]), np.min(outline[:, 1])) == (0.5, -4.5)
    assert (np.min(outline[:, 0]), np.max(outline[:, 0])) == (9.5, 39.5)

    bottom = np.zeros((50, 50), dtype=bool)
    bottom[45:, :] = True
    outline = Aperture.from_mask(bottom).outer
    assert (np.max(outline[:, 1]), np.min(outline[:, 1])) == (-44.5, -49.5)


def test_mask_is_a_read_only_copy_and_numeric_masks_work() -> None:
    source = np.zeros((20, 20), dtype=np.uint8)
    source[5:15, 5:15] = 255
    aperture = Aperture.from_mask(source)
    assert aperture.mask.dtype == np.bool_ and aperture.shape == (20, 20)
    assert not aperture.mask.flags.writeable
    with pytest.raises(ValueError):
        aperture.mask[0, 0] = True
    for polygon in aperture.outers:
        assert not polygon.flags.writeable
    source[:] = 0
    assert aperture.valid_count == 100
    assert np.array_equal(aperture.mask, _region(aperture))

    as_bool = np.zeros((20, 20), dtype=bool)
    as_bool[5:15, 5:15] = True
    aperture = Aperture.from_mask(as_bool)
    as_bool[:] = False  # a bool input is copied too
    assert aperture.valid_count == 100

    floats = np.where(np.arange(400).reshape(20, 20) % 3 == 0, 0.25, 0.0)
    assert Aperture.from_mask(floats).valid_count == int(np.count_nonzero(floats))


def test_describe_names_topology_counts_and_pixels() -> None:
    mask = _disk((101, 101), 50, 50, 40.0) & ~_disk((101, 101), 50, 50, 15.0)
    text = Aperture.from_mask(mask).describe()
    assert text == f"doubly connected: 1 component, 1 hole, {int(mask.sum())} valid pixels"
    mask[50, 30] = False  # a 1-px hole in the ring, below the 4-px threshold
    assert "1 hole smaller than 4 px ignored" in Aperture.from_mask(mask).describe()


# --------------------------------------------------------------------- enclosing circle


def _max_centre_distance(mask: NDArray[np.bool_], cx: float, cy: float) -> float:
    rows, cols = np.nonzero(mask)
    return float(np.max(np.hypot(cols - cx, rows - cy)))


def test_enclosing_circle_of_a_disk_is_the_disk() -> None:
    mask = _disk((101, 101), 50, 50, 40.0)
    cx, cy, r = Aperture.from_mask(mask).enclosing_circle()
    # The valid centres (50 +- 40, 50) are 80 px apart, so the minimum circle has radius 40
    # about (50, 50); OpenCV locates the centre in float32 (1e-3 px is generous).
    assert (cx, cy, r) == pytest.approx((50.0, 50.0, 40.0), abs=1e-3)
    assert _max_centre_distance(mask, cx, cy) / r <= 1.0


@pytest.mark.parametrize(
    ("name", "mask", "expected"),
    [
        # Symmetric under x -> -x and y -> -y: the unique minimum circle is centred at (110, 110).
        ("butterfly", _butterfly(), (110.0, 110.0)),
        # Two disks of radius 10 at columns 20 and 80 on row 20: extreme centres at columns 10
        # and 90, so the circle is centred at (col 50, row 20) with radius 40.
        (
            "two disks",
            _disk((41, 101), 20, 20, 10.0) | _disk((41, 101), 20, 80, 10.0),
            (50.0, 20.0),
        ),
    ],
)
def test_enclosing_circle_contains_every_valid_centre(
    name: str, mask: NDArray[np.bool_], expected: tuple[float, float]
) -> None:
    cx, cy, r = Aperture.from_mask(mask).enclosing_circle()
    assert (cx, cy) == pytest.approx(expected, abs=1e-3), name
    farthest = _max_centre_distance(mask, cx, cy)
    assert farthest / r <= 1.0
    assert r <= farthest * (1 + 1e-8)  # and no bigger than needed about that centre


def test_enclosing_circle_of_a_single_pixel() -> None:
    mask = np.zeros((5, 6), dtype=bool)
    mask[2, 3] = True
    cx, cy, r = Aperture.from_mask(mask).enclosing_circle()
    assert (cx, cy) == (3.0, 2.0) and 0.0 < r < 1e-9


# -------------------------------------------------------------- complicated outlines


@pytest.mark.parametrize("name", ["butterfly", "rounded rectangle"])
def test_complicated_outlines_are_simple(name: str) -> None:
    mask = _butterfly() if name == "butterfly" else _rounded_rectangle()
    aperture = Aperture.from_mask(mask)
    assert aperture.topology is Topology.SIMPLY_CONNECTED
    outline = aperture.outer
    assert len(outline) > 300  # CHAIN_APPROX_NONE: one vertex per boundary pixel at least
    assert _is_simple(outline)
    assert _shoelace(outline) > 0
    count = int(mask.sum())
    assert abs(_shoelace(outline) - count) <= 0.01 * count  # as for the disk
    assert np.array_equal(_region(aperture), mask)


@settings(max_examples=200, deadline=None, database=None)
@given(
    mask=arrays(np.bool_, st.tuples(st.integers(1, 12), st.integers(1, 12))),
    threshold=st.sampled_from([0.0, 1.0, 2.0, 4.0]),
)
def test_random_masks_give_consistent_topology_and_simple_polygons(
    mask: NDArray[np.bool_], threshold: float
) -> None:
    if not mask.any():
        with pytest.raises(EmptyAperture):
            Aperture.from_mask(mask)
        return
    aperture = Aperture.from_mask(mask, min_hole_area_px=threshold)

    # Independent count: 8-connected foreground, 4-connected background of the padded mask;
    # holes are the background components that do not reach the padding.
    _, components = ndimage.label(mask, structure=np.ones((3, 3)))
    background, n_background = ndimage.label(np.pad(~mask, 1, constant_values=True))
    sizes = np.bincount(background.ravel(), minlength=n_background + 1)
    hole_labels = [k for k in range(1, n_background + 1) if k != background[0, 0]]
    small = [k for k in hole_labels if sizes[k] < threshold]
    assert aperture.components == components == len(aperture.outers)
    assert len(aperture.holes) + aperture.ignored_holes == len(hole_labels)
    assert aperture.ignored_holes == len(small)
    kept = len(hole_labels) - len(small)
    if components == 1 and kept <= 1:
        expected = Topology.SIMPLY_CONNECTED if kept == 0 else Topology.DOUBLY_CONNECTED
    else:
        expected = Topology.UNSUPPORTED
    assert aperture.topology is expected

    polygons = aperture.outers + aperture.holes
    assert all(_shoelace(p) > 0 for p in aperture.outers)
    assert all(_shoelace(p) < 0 for p in aperture.holes)
    assert all(_is_simple(p) for p in polygons)
    assert all(_disjoint(p, q) for i, p in enumerate(polygons) for q in polygons[i + 1 :])
    # Even-odd inside the polygons = the valid pixels plus the ignored holes (a hole of fewer
    # than 4 px cannot enclose an island, so no nesting is lost).
    filled = mask | np.isin(background[1:-1, 1:-1], small)
    assert np.array_equal(_region(aperture), filled)
    assert _vertices_in_valid_pixel_squares(aperture)
    cx, cy, r = aperture.enclosing_circle()
    assert _max_centre_distance(mask, cx, cy) <= r
