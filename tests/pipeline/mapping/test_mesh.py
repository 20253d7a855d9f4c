"""Tests for wavestack.pipeline.mapping.mesh (aperture meshes) and wavestack.pipeline.mapping.pixel_location.

Every figure is computed here from the mesh with helpers written independently of the
package: conformity from the triangles' half-edges, Euler characteristic, exact point to
segment distances, interior angles and cotangent weights, barycentric containment.
Coordinates are physical pixels, x = col and y = -row.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial import Delaunay

from wavestack.pipeline.mapping import mesh as mesh_module
from wavestack.pipeline.aperture.region import Aperture, UnsupportedAperture
from wavestack.pipeline.mapping.mesh import TriMesh, mesh_aperture
from wavestack.pipeline.mapping.pixel_location import PixelLocation, locate_points

_ON_POLYGON_PX = 1e-9  # boundary vertices are interpolated on polygon edges: float rounding only
# Smallest interior angle allowed on the test shapes, in degrees. None of them has a convex
# corner sharper than 90 degrees, so the angles come from the lattice (60 degrees) and the
# band of Delaunay triangles between it and the boundary; measured minima are 26.4-31.7
# degrees. 20 degrees leaves room for rounding and platform
# differences in Qhull and still fails on slivers from a broken clearance/encroachment rule
# (which give single-digit angles).
_MIN_ANGLE_DEG = 20.0
_COT_TOL = 1e-9  # cot(a) + cot(b) >= -tol: zero for cocircular quads up to rounding
_COUNT_RTOL = 0.15  # vertex count within 15 % of the target (the mesher aims for 3 %)
# Edge lengths in units of h: lattice edges are h, boundary chords about h (0.67-1.5 h next to
# corners), band edges join points at least ~0.7 h apart (clearance of the lattice from the
# boundary) across gaps below ~1.9 h; measured 0.70-1.87 h. [0.5, 2] catches slivers and holes
# in the lattice.
_EDGE_RANGE = (0.5, 2.0)
# |mesh area - polygon area| / perimeter, in px: a chord deviates from the staircase polygon
# by at most ~0.5 px, with alternating signs; measured <= 0.037 px. 0.1 px catches a cut
# corner or a lost feature.
_AREA_PER_PERIMETER_PX = 0.1
_REPRODUCE_PX = 1e-9  # W @ vertices == point: barycentric algebra, rounding only
_OUTSIDE_FRACTION = 0.005  # pixel centres of the mask outside the polygonal mesh
_OUTSIDE_DEPTH_PX = 1.0  # how far outside the mesh such a pixel centre may lie


# ----------------------------------------------------------------------------- shapes


def _grid(size: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Physical (x, y) of the pixel centres of a size x size image, relative to its centre."""
    rows, cols = np.mgrid[:size, :size].astype(np.float64)
    centre = (size - 1) / 2.0
    return cols - centre, centre - rows


def _disk_mask(size: int = 512, radius: float = 240.0) -> NDArray[np.bool_]:
    x, y = _grid(size)
    return np.hypot(x, y) <= radius


def _butterfly_mask(size: int = 512, r_max: float = 245.0) -> NDArray[np.bool_]:
    """The star-shaped 'butterfly' r(t) = 1 + 0.25 cos 2t - 0.38 cos 4t, scaled to r_max."""
    x, y = _grid(size)
    t = np.linspace(0.0, 2.0 * np.pi, 20001)
    peak = np.max(1.0 + 0.25 * np.cos(2 * t) - 0.38 * np.cos(4 * t))
    theta = np.arctan2(y, x)
    r = 1.0 + 0.25 * np.cos(2 * theta) - 0.38 * np.cos(4 * theta)
    return np.hypot(x, y) <= r_max * r / peak


def _rounded_rectangle_mask(
    size: int = 512, width: float = 448.0, height: float = 128.0, corner: float = 24.0
) -> NDArray[np.bool_]:
    """3.5:1 rectangle with rounded corners."""
    x, y = _grid(size)
    dx = np.maximum(np.abs(x) - (width / 2 - corner), 0.0)
    dy = np.maximum(np.abs(y) - (height / 2 - corner), 0.0)
    return np.hypot(dx, dy) <= corner


def _eccentric_annulus_mask(
    size: int = 512, outer: float = 240.0, inner: float = 120.0, gap: float = 9.0
) -> NDArray[np.bool_]:
    """Outer circle with an off-centre circular hole leaving a ``gap`` px wall on one side."""
    x, y = _grid(size)
    shift = outer - inner - gap
    return (np.hypot(x, y) <= outer) & (np.hypot(x - shift, y) > inner)


def _triangle_hole_mask(
    size: int = 512, outer: float = 240.0, apothem: float = 55.0
) -> NDArray[np.bool_]:
    """Disk with an equilateral triangular hole (apex up) at its centre."""
    x, y = _grid(size)
    in_triangle = np.ones_like(x, dtype=bool)
    for k in range(3):
        angle = -np.pi / 2 + 2 * np.pi * k / 3  # outward normals of the three sides
        in_triangle &= x * np.cos(angle) + y * np.sin(angle) <= apothem
    return (np.hypot(x, y) <= outer) & ~in_triangle


_SHAPES = {
    "disk": _disk_mask,
    "butterfly": _butterfly_mask,
    "rounded_rectangle": _rounded_rectangle_mask,
    "eccentric_annulus": _eccentric_annulus_mask,
    "triangle_hole": _triangle_hole_mask,
}
_TARGETS = (15000, 5000)


@pytest.fixture(
    scope="module",
    params=[(shape, target) for shape in _SHAPES for target in _TARGETS],
    ids=lambda p: f"{p[0]}-{p[1]}",
)
def meshed(request: pytest.FixtureRequest) -> tuple[Aperture, TriMesh, int]:
    """(aperture, mesh, target) for every shape and target, built once per module."""
    shape, target = request.param
    aperture = Aperture.from_mask(_SHAPES[shape]())
    return aperture, mesh_aperture(aperture, target), target


# ----------------------------------------------------------------------------- helpers


def _polygons(aperture: Aperture) -> list[NDArray[np.float64]]:
    return [aperture.outer] if aperture.hole is None else [aperture.outer, aperture.hole]


def _shoelace(polygon: NDArray[np.float64]) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _perimeter(polygon: NDArray[np.float64]) -> float:
    return float(np.sum(np.hypot(*(np.roll(polygon, -1, axis=0) - polygon).T)))


def _segment_distance(
    points: NDArray[np.float64], starts: NDArray[np.float64], ends: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Exact distance from each point to the nearest of the segments, chunked over points."""
    out = np.empty(len(points))
    ab = ends - starts
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    for lo in range(0, len(points), 256):
        p = points[lo : lo + 256, None, :]
        t = np.clip(np.sum((p - starts) * ab, axis=2) / length2, 0.0, 1.0)
        gap = p - starts - t[..., None] * ab
        out[lo : lo + 256] = np.sqrt(np.min(np.sum(gap * gap, axis=2), axis=1))
    return out


def _polygon_distance(
    points: NDArray[np.float64], polygon: NDArray[np.float64]
) -> NDArray[np.float64]:
    return _segment_distance(points, polygon, np.roll(polygon, -1, axis=0))


def _pairwise_segment_distance(
    points: NDArray[np.float64], starts: NDArray[np.float64], ends: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance from points[i] to the segment starts[i]-ends[i], shape (N,)."""
    ab = ends - starts
    t = np.clip(np.sum((points - starts) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    return np.linalg.norm(points - starts - t[:, None] * ab, axis=1)


def _directed(starts: NDArray[np.int64], ends: NDArray[np.int64]) -> set[tuple[int, int]]:
    return set(zip(starts.tolist(), ends.tolist(), strict=True))


def _loop_chords(mesh: TriMesh) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    starts = np.concatenate(mesh.boundary_loops)
    ends = np.concatenate([np.roll(loop, -1) for loop in mesh.boundary_loops])
    return starts, ends


def _boundary_half_edges(triangles: NDArray[np.int64]) -> set[tuple[int, int]]:
    """Directed edges of the triangles whose reverse is not an edge of any triangle."""
    half = {
        (int(a), int(b))
        for tri in triangles
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0]))
    }
    return {(a, b) for a, b in half if (b, a) not in half}


def _edge_triangle_counts(mesh: TriMesh) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Undirected edge keys i * V + j (i < j) and how many triangles hold each."""
    t = mesh.triangles
    pairs = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    low, high = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    keys = low * mesh.n_vertices + high
    return np.unique(keys, return_counts=True)


def _angles_deg(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Interior angles, shape (T, 3), from the law of cosines."""
    p = vertices[triangles]
    side = [np.linalg.norm(p[:, (k + 2) % 3] - p[:, (k + 1) % 3], axis=1) for k in range(3)]
    angles = []
    for k in range(3):
        a, b, c = side[k], side[(k + 1) % 3], side[(k + 2) % 3]
        angles.append(np.degrees(np.arccos(np.clip((b * b + c * c - a * a) / (2 * b * c), -1, 1))))
    return np.column_stack(angles)


def _interior_cot_sums(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64]
) -> NDArray[np.float64]:
    """cot(alpha) + cot(beta) of every edge shared by two triangles (twice its cot weight)."""
    n = len(vertices)
    keys, cots = [], []
    for k in range(3):
        i, j, o = triangles[:, (k + 1) % 3], triangles[:, (k + 2) % 3], triangles[:, k]
        u, w = vertices[i] - vertices[o], vertices[j] - vertices[o]
        cots.append(np.sum(u * w, axis=1) / np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]))
        keys.append(np.minimum(i, j) * n + np.maximum(i, j))
    _, inverse, counts = np.unique(
        np.concatenate(keys), return_inverse=True, return_counts=True
    )
    sums = np.bincount(inverse, weights=np.concatenate(cots))
    assert counts.max() <= 2, "an edge is shared by more than two triangles"
    return sums[counts == 2]


def _triangle_areas(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64]
) -> NDArray[np.float64]:
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])


def _inside_polygon(
    points: NDArray[np.float64], polygon: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Even-odd ray casting towards +x (brute force over all edges)."""
    x, y = points[:, :1], points[:, 1:]
    x1, y1 = polygon[None, :, 0], polygon[None, :, 1]
    x2, y2 = np.roll(polygon[:, 0], -1)[None], np.roll(polygon[:, 1], -1)[None]
    straddles = (y1 > y) != (y2 > y)
    x_cross = x1 + (y - y1) * (x2 - x1) / np.where(straddles, y2 - y1, 1.0)
    return np.count_nonzero(straddles & (x < x_cross), axis=1) % 2 == 1


def _sorted_rows(triangles: NDArray[np.int64]) -> NDArray[np.int64]:
    """Triangles as sorted vertex triples, rows in lexicographic order (for set equality)."""
    rows = np.sort(triangles, axis=1)
    return rows[np.lexsort(rows.T[::-1])]


def _pixel_centres(mask: NDArray[np.bool_]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    rows, cols = np.nonzero(mask)
    return cols.astype(np.float64), -rows.astype(np.float64)


def _assert_conforming(mesh: TriMesh) -> None:
    """Boundary half-edges == directed loop chords; every vertex used; CCW; Delaunay."""
    starts, ends = _loop_chords(mesh)
    assert _boundary_half_edges(mesh.triangles) == _directed(starts, ends)
    assert np.array_equal(np.unique(mesh.triangles), np.arange(mesh.n_vertices))
    assert _triangle_areas(mesh.vertices, mesh.triangles).min() > 0
    assert _interior_cot_sums(mesh.vertices, mesh.triangles).min() >= -_COT_TOL


# ----------------------------------------------------------------------------- mesh


def test_vertex_count_near_target(meshed: tuple[Aperture, TriMesh, int]) -> None:
    _, mesh, target = meshed
    assert abs(mesh.n_vertices / target - 1.0) < _COUNT_RTOL
    assert mesh.vertices.shape == (mesh.n_vertices, 2)
    assert mesh.vertices.dtype == np.float64 and mesh.triangles.dtype == np.int64


def test_triangles_counter_clockwise_and_tile_the_loops(
    meshed: tuple[Aperture, TriMesh, int],
) -> None:
    aperture, mesh, _ = meshed
    areas = _triangle_areas(mesh.vertices, mesh.triangles)
    assert areas.min() > 0
    np.testing.assert_allclose(mesh.triangle_areas(), areas, rtol=1e-12)
    enclosed = sum(_shoelace(mesh.vertices[loop]) for loop in mesh.boundary_loops)
    assert abs(areas.sum() - enclosed) < 1e-9 * enclosed  # no overlap, no gap
    polygons = _polygons(aperture)
    polygon_area = sum(_shoelace(p) for p in polygons)
    perimeter = sum(_perimeter(p) for p in polygons)
    assert abs(areas.sum() - polygon_area) < _AREA_PER_PERIMETER_PX * perimeter


def test_boundary_edges_are_exactly_the_loops(meshed: tuple[Aperture, TriMesh, int]) -> None:
    aperture, mesh, _ = meshed
    assert len(mesh.boundary_loops) == (1 if aperture.hole is None else 2)
    starts, ends = _loop_chords(mesh)
    assert _boundary_half_edges(mesh.triangles) == _directed(starts, ends)
    assert _shoelace(mesh.vertices[mesh.boundary_loops[0]]) > 0  # outer counter-clockwise
    if aperture.hole is not None:
        assert _shoelace(mesh.vertices[mesh.boundary_loops[1]]) < 0  # hole clockwise
    boundary = mesh.boundary_indices
    assert len(np.unique(boundary)) == len(boundary)  # no vertex repeated, no closing repeat
    interior = mesh.interior_indices
    everything = np.sort(np.concatenate([boundary, interior]))
    assert np.array_equal(everything, np.arange(mesh.n_vertices))


def test_euler_characteristic_and_manifold(meshed: tuple[Aperture, TriMesh, int]) -> None:
    aperture, mesh, _ = meshed
    keys, counts = _edge_triangle_counts(mesh)
    assert counts.max() <= 2
    edges = mesh.edges()
    assert len(edges) == len(keys) and np.all(edges[:, 0] < edges[:, 1])
    euler = mesh.n_vertices - len(edges) + len(mesh.triangles)
    assert euler == (1 if aperture.hole is None else 0)
    assert np.array_equal(np.unique(mesh.triangles), np.arange(mesh.n_vertices))  # all used


def test_boundary_vertices_lie_on_the_polygons(meshed: tuple[Aperture, TriMesh, int]) -> None:
    aperture, mesh, _ = meshed
    for loop, polygon in zip(mesh.boundary_loops, _polygons(aperture), strict=True):
        distance = _polygon_distance(mesh.vertices[loop], polygon)
        assert distance.max() < _ON_POLYGON_PX


def test_min_angle_and_edge_lengths(meshed: tuple[Aperture, TriMesh, int]) -> None:
    _, mesh, _ = meshed
    angles = _angles_deg(mesh.vertices, mesh.triangles)
    assert angles.min() >= _MIN_ANGLE_DEG
    assert mesh.min_angle_deg() == pytest.approx(angles.min(), abs=1e-6)
    edges = mesh.edges()
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    assert _EDGE_RANGE[0] * mesh.spacing <= lengths.min()
    assert lengths.max() <= _EDGE_RANGE[1] * mesh.spacing


def test_interior_cotangent_weights_non_negative(meshed: tuple[Aperture, TriMesh, int]) -> None:
    _, mesh, _ = meshed
    assert _interior_cot_sums(mesh.vertices, mesh.triangles).min() >= -_COT_TOL


def test_equals_qhull_delaunay_of_all_vertices(meshed: tuple[Aperture, TriMesh, int]) -> None:
    # The mesher runs Qhull only near the boundary and takes the deep lattice triangles as
    # they are; the result must be the Delaunay triangulation of all its vertices restricted
    # to the domain. Qhull also returns zero-area slivers between collinear boundary
    # vertices on the convex hull; those are not triangles and are left out of the comparison.
    _, mesh, _ = meshed
    simplices = Delaunay(mesh.vertices).simplices
    centroids = mesh.vertices[simplices].mean(axis=1)
    in_domain = np.zeros(len(simplices), dtype=bool)
    for loop in mesh.boundary_loops:
        in_domain ^= _inside_polygon(centroids, mesh.vertices[loop])
    area = np.abs(_triangle_areas(mesh.vertices, simplices))
    expected = simplices[in_domain & (area > 1e-9 * mesh.spacing**2)]
    assert np.array_equal(_sorted_rows(expected), _sorted_rows(mesh.triangles))


def test_cotangent_check_detects_a_non_delaunay_edge() -> None:
    # A flat rhombus split along its long diagonal: the shared edge faces two angles of
    # 2 atan(1 / 0.3) = 147 degrees, so cot + cot = 2 cot(147 deg) < 0 (the flipped diagonal
    # would be the Delaunay one); the helper must report it (guards the test above).
    vertices = np.array([[0.0, 0.0], [1.0, -0.3], [2.0, 0.0], [1.0, 0.3]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])  # shared edge 0-2, the long diagonal
    assert _interior_cot_sums(vertices, triangles).min() < -0.5


def test_sharp_rectangle_corners_are_vertices() -> None:
    mask = np.zeros((512, 512), dtype=bool)
    mask[192:320, 32:480] = True  # 448 x 128 px, 3.5:1
    mesh = mesh_aperture(Aperture.from_mask(mask), 5000)
    outer = mesh.vertices[mesh.boundary_loops[0]]
    for corner in [(31.5, -191.5), (479.5, -191.5), (479.5, -319.5), (31.5, -319.5)]:
        assert np.min(np.hypot(*(outer - corner).T)) == 0.0
    _assert_conforming(mesh)
    assert mesh.min_angle_deg() >= 30.0  # right angles and straight sides: no thin triangle


@pytest.mark.parametrize("gap", [1.0, 2.0, 3.0])
@pytest.mark.parametrize("target", [1000, 5000])
def test_narrow_gap_annulus_conforms(gap: float, target: int) -> None:
    # Gaps far below the spacing (h ~ 13 px for 1000 vertices): Delaunay must still give
    # every boundary chord, and the triangles stay Delaunay (angles may get small there).
    aperture = Aperture.from_mask(_eccentric_annulus_mask(gap=gap))
    mesh = mesh_aperture(aperture, target)
    _assert_conforming(mesh)
    assert mesh.n_vertices - len(mesh.edges()) + len(mesh.triangles) == 0


def _comb_disk() -> NDArray[np.bool_]:
    """Disk with five 1 px slits cut in from its left edge, 350 px long, 60 px apart."""
    mask = _disk_mask()
    for k in range(5):
        mask[100 + 60 * k, :350] = False
    return mask


def test_missing_boundary_chords_are_split(monkeypatch: pytest.MonkeyPatch) -> None:
    # With h ~ 30 px the two sides of each slit are 1 px apart and Delaunay connects across
    # them; the mesher must split those chords (on the polygon) until they are recovered.
    # (This case needs about 40 splits over 3 rounds, so it keeps exercising the repair if
    # the mesher's constants are retuned.)
    splits: list[int] = []
    real_split = mesh_module._split

    def counting_split(
        s: NDArray[np.float64], missing: NDArray[np.bool_], length: float
    ) -> NDArray[np.float64]:
        splits.append(int(missing.sum()))
        return real_split(s, missing, length)

    monkeypatch.setattr(mesh_module, "_split", counting_split)
    aperture = Aperture.from_mask(_comb_disk())
    mesh = mesh_aperture(aperture, 500)
    assert sum(splits) > 0, "this case is meant to exercise the boundary repair"
    _assert_conforming(mesh)
    distance = _polygon_distance(mesh.vertices[mesh.boundary_loops[0]], aperture.outer)
    assert distance.max() < _ON_POLYGON_PX
    assert mesh.n_vertices - len(mesh.edges()) + len(mesh.triangles) == 1


def test_unrecovered_boundary_raises(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(mesh_module, "_REPAIR_ROUNDS", 1)
    with pytest.raises(RuntimeError, match="did not recover the aperture boundary"):
        mesh_aperture(Aperture.from_mask(_comb_disk()), 500)


def test_unsupported_apertures_raise() -> None:
    x, y = _grid(400)
    two_disks = (np.hypot(x + 100, y) <= 60) | (np.hypot(x - 100, y) <= 60)
    with pytest.raises(UnsupportedAperture, match="2 components"):
        mesh_aperture(Aperture.from_mask(two_disks))
    x, y = _grid(512)
    two_holes = _disk_mask() & (np.hypot(x - 100, y) > 40) & (np.hypot(x + 100, y) > 40)
    with pytest.raises(UnsupportedAperture, match="2 holes"):
        mesh_aperture(Aperture.from_mask(two_holes))


@pytest.mark.parametrize("bad", [15, 0, -5, 1000.0, True, "5000"])
def test_rejects_bad_target(bad: object) -> None:
    with pytest.raises(ValueError, match="target_vertices"):
        mesh_aperture(Aperture.from_mask(_disk_mask(64, 20.0)), bad)  # type: ignore[arg-type]


def test_deterministic_and_read_only() -> None:
    first = mesh_aperture(Aperture.from_mask(_eccentric_annulus_mask()), 5000)
    second = mesh_aperture(Aperture.from_mask(_eccentric_annulus_mask()), 5000)
    assert np.array_equal(first.vertices, second.vertices)
    assert np.array_equal(first.triangles, second.triangles)
    assert len(first.boundary_loops) == len(second.boundary_loops) == 2
    for a, b in zip(first.boundary_loops, second.boundary_loops, strict=True):
        assert np.array_equal(a, b)
    assert first.spacing == second.spacing
    for array in (first.vertices, first.triangles, *first.boundary_loops):
        assert not array.flags.writeable


def test_small_apertures() -> None:
    # A 5 x 5 px square with the smallest target, and far more vertices than pixels.
    mask = np.zeros((20, 20), dtype=bool)
    mask[5:10, 5:10] = True
    aperture = Aperture.from_mask(mask)
    for target in (16, 2000):
        mesh = mesh_aperture(aperture, target)
        _assert_conforming(mesh)
        assert abs(mesh.n_vertices / target - 1.0) < 0.25  # few vertices: coarse rounding
        on_polygon = _polygon_distance(mesh.vertices[mesh.boundary_loops[0]], aperture.outer)
        assert on_polygon.max() < _ON_POLYGON_PX


# ----------------------------------------------------------------------------- pixel location


@pytest.fixture(scope="module")
def big_disk() -> tuple[Aperture, TriMesh]:
    """1024 x 1024 image, disk of radius 448 px (about 630k pixels), 15k-vertex mesh."""
    aperture = Aperture.from_mask(_disk_mask(1024, 448.0))
    return aperture, mesh_aperture(aperture, 15000)


def _check_weights(
    mesh: TriMesh, x: NDArray[np.float64], y: NDArray[np.float64]
) -> PixelLocation:
    """Locate and check the invariants every result must satisfy; return the location."""
    location = locate_points(mesh, x, y)
    n = len(x)
    weights = location.weights
    assert weights.shape == (n, mesh.n_vertices)
    assert np.array_equal(np.diff(weights.indptr), np.full(n, 3))
    np.testing.assert_allclose(np.asarray(weights.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    # The stored columns are the vertices of the reported triangle.
    columns = np.sort(weights.indices.reshape(n, 3), axis=1)
    assert np.array_equal(columns, np.sort(mesh.triangles[location.triangle], axis=1))
    reproduced = weights @ mesh.vertices
    assert np.abs(reproduced - np.column_stack((x, y))).max() < _REPRODUCE_PX
    inside_data = weights.data.reshape(n, 3)[~location.outside]
    assert inside_data.min(initial=0.0) >= 0.0 and inside_data.max(initial=1.0) <= 1.0
    return location


def test_random_interior_points(meshed: tuple[Aperture, TriMesh, int]) -> None:
    _, mesh, _ = meshed
    rng = np.random.default_rng(7)
    tri = rng.integers(0, len(mesh.triangles), 20000)
    bary = rng.dirichlet(np.ones(3), len(tri))
    points = np.einsum("nk,nkd->nd", bary, mesh.vertices[mesh.triangles[tri]])
    location = _check_weights(mesh, points[:, 0], points[:, 1])
    assert not location.outside.any()
    # The reported triangle holds the point (its own barycentric coordinates are >= 0).
    corners = mesh.vertices[mesh.triangles[location.triangle]]
    area = _triangle_areas(mesh.vertices, mesh.triangles[location.triangle])
    for k in range(3):
        a, b = corners[:, (k + 1) % 3], corners[:, (k + 2) % 3]
        sub = 0.5 * ((b - a)[:, 0] * (points - a)[:, 1] - (b - a)[:, 1] * (points - a)[:, 0])
        assert np.all(sub / area >= -1e-9)


def test_vertices_locate_onto_themselves(meshed: tuple[Aperture, TriMesh, int]) -> None:
    _, mesh, _ = meshed
    location = _check_weights(mesh, mesh.vertices[:, 0], mesh.vertices[:, 1])
    assert not location.outside.any()  # boundary vertices count as inside (on an edge)
    diagonal = location.weights.diagonal()
    np.testing.assert_allclose(diagonal, 1.0, atol=1e-9)


@pytest.mark.parametrize("shape", ["big_disk", "butterfly"])
def test_mask_pixel_centres_are_inside(shape: str, big_disk: tuple[Aperture, TriMesh]) -> None:
    # The mesh boundary is made of chords between points of the polygon, which lies half a
    # pixel outside the boundary pixel centres; a chord cuts a staircase corner by at most
    # ~0.5 px, so only a few boundary pixel centres fall outside, and barely.
    if shape == "big_disk":
        aperture, mesh = big_disk
    else:
        aperture = Aperture.from_mask(_butterfly_mask())
        mesh = mesh_aperture(aperture, 15000)
    x, y = _pixel_centres(aperture.mask)
    location = _check_weights(mesh, x, y)
    assert location.outside.mean() < _OUTSIDE_FRACTION
    starts, ends = _loop_chords(mesh)
    outside = np.column_stack((x, y))[location.outside]
    depth = _segment_distance(outside, mesh.vertices[starts], mesh.vertices[ends])
    assert depth.max(initial=0.0) < _OUTSIDE_DEPTH_PX


def test_outside_points_extrapolate_from_the_nearest_boundary_triangle() -> None:
    # Coarse mesh (h ~ 13 px) of the annulus with a triangular hole: its reflex corners are
    # where the nearest boundary vertex's edges are not always the nearest edge.
    mesh = mesh_aperture(Aperture.from_mask(_triangle_hole_mask()), 1000)
    rng = np.random.default_rng(3)
    samples = []
    for loop in mesh.boundary_loops:  # points 0.2-30 px to the right of a chord (outside it)
        a = mesh.vertices[loop]
        pick = rng.integers(0, len(a), 1000)
        b = np.roll(a, -1, axis=0)[pick]
        tangent = b - a[pick]
        normal = np.column_stack((tangent[:, 1], -tangent[:, 0]))
        normal /= np.linalg.norm(tangent, axis=1)[:, None]
        base = a[pick] + rng.random(1000)[:, None] * tangent
        samples.append(base + normal * rng.uniform(0.2, 30.0, 1000)[:, None])
    points = np.vstack(samples)
    location = _check_weights(mesh, points[:, 0], points[:, 1])
    # Outside flags agree with an even-odd test against the loops (some samples near the
    # hole's tips cross back into the domain).
    expected = np.ones(len(points), dtype=bool)
    for loop in mesh.boundary_loops:
        expected ^= _inside_polygon(points, mesh.vertices[loop])
    assert np.array_equal(location.outside, expected)
    assert expected.mean() > 0.9
    assert location.weights.data.reshape(-1, 3)[location.outside].min() < 0  # extrapolated
    # The chosen triangle holds a boundary chord at the minimum distance over all chords.
    starts, ends = _loop_chords(mesh)
    outside = points[location.outside]
    best = _segment_distance(outside, mesh.vertices[starts], mesh.vertices[ends])
    chords = set(zip(starts.tolist(), ends.tolist(), strict=True))
    held_distance = np.full(len(outside), np.inf)
    for k in range(3):
        a = mesh.triangles[location.triangle[location.outside], k]
        b = mesh.triangles[location.triangle[location.outside], (k + 1) % 3]
        pairs = zip(a.tolist(), b.tolist(), strict=True)
        is_chord = np.array([pair in chords for pair in pairs])
        distance = _pairwise_segment_distance(outside, mesh.vertices[a], mesh.vertices[b])
        held_distance = np.minimum(held_distance, np.where(is_chord, distance, np.inf))
    assert np.all(held_distance <= best + 1e-9)


def test_far_points_and_empty_input(big_disk: tuple[Aperture, TriMesh]) -> None:
    _, mesh = big_disk
    x = np.array([-5000.0, 0.0, 5000.0, 511.5])
    y = np.array([0.0, 3000.0, -511.5, -511.5])  # last one: the disk centre
    location = _check_weights(mesh, x, y)
    assert location.outside.tolist() == [True, True, True, False]
    empty = locate_points(mesh, np.empty(0), np.empty(0))
    assert empty.weights.shape == (0, mesh.n_vertices) and empty.outside.shape == (0,)


def test_locate_rejects_bad_input(big_disk: tuple[Aperture, TriMesh]) -> None:
    _, mesh = big_disk
    with pytest.raises(ValueError, match="shape"):
        locate_points(mesh, np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="NaN or infinite"):
        locate_points(mesh, np.array([0.0, math.nan]), np.zeros(2))
