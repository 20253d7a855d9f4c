"""The interior of an aperture mesh: the equilateral lattice, its clearance from the boundary, and
the Delaunay triangulation of the band along the boundary (steps 2 to 4 of
:func:`~wavestack.pipeline.mapping.mesh.mesh_aperture`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import Delaunay, cKDTree

from .mesh_boundary import _chords, _Curve, _loop_indices, _resample
from .mesh_geometry import _member, _signed_areas, _unique_edges


_LATTICE_DENSITY = 2.0 / math.sqrt(3.0)  # points per h^2 of an equilateral lattice of spacing h
_CLEARANCE = 0.7  # lattice points closer than this many h to the boundary are dropped


# Lattice points at least _DEEP h from the boundary (sampled distance, <= 0.05 h too large)
# are "deep"; lattice triangles of three deep points are kept without Delaunay: any point of
# their circumdisk is within 2 h / sqrt(3) = 1.155 h of each vertex, so no boundary vertex
# is in it. Qhull gets the lattice points nearer than (_DEEP + _NEAR_MARGIN) h: every point
# farther away has six deep neighbours, so its whole star is made of core triangles.
_DEEP = 1.3
_NEAR_MARGIN = 1.25
_SAMPLE_STEP = 0.1  # spacing of the boundary sampling used for distances, in units of h
_COUNT_TOLERANCE = 0.03  # relative vertex-count error below which h is accepted
_SPACING_ROUNDS = 4  # estimates of h at most (the first from the area, then corrections)
_DEGENERATE_AREA = 1e-12  # Qhull triangles below this many h^2 are flat slivers, dropped


@dataclass(frozen=True, eq=False)
class _Lattice:
    """Equilateral triangular lattice of spacing h on a (rows, cols) grid.

    Point (i, j) (column i, row j) is at ``origin + (i h + (j mod 2) h / 2, j h sqrt(3) / 2)``;
    ``points`` lists them row by row (flat index ``j * cols + i``). In skew coordinates
    ``a = i - j // 2``, ``b = j`` the points are ``origin + a e1 + b e2`` with e1 = (h, 0),
    e2 = (h / 2, h sqrt(3) / 2); the skew cell of corner (a, b) holds the lower triangle
    (a, b), (a + 1, b), (a, b + 1) and the upper triangle (a + 1, b), (a + 1, b + 1),
    (a, b + 1), both counter-clockwise, with ids ``2 * (j * cols + i)`` and that plus 1.
    """

    origin: tuple[float, float]
    h: float
    rows: int
    cols: int
    points: NDArray[np.float64]

    @classmethod
    def covering(cls, low: NDArray[np.float64], high: NDArray[np.float64], h: float) -> _Lattice:
        """Lattice covering the box [low, high] with a margin of one spacing."""
        dy = h * math.sqrt(3.0) / 2.0
        origin = (float(low[0]) - h, float(low[1]) - h)
        rows = int((high[1] - origin[1]) / dy) + 3
        cols = int((high[0] - origin[0]) / h) + 3
        j, i = np.divmod(np.arange(rows * cols), cols)
        points = np.column_stack(
            (origin[0] + h * (i + 0.5 * (j % 2)), origin[1] + dy * j)
        )
        return cls(origin=origin, h=h, rows=rows, cols=cols, points=points)

    def triangles(self) -> NDArray[np.int64]:
        """Flat point indices of every triangle, shape (2 * rows * cols, 3), by id.

        Triangles that would reach outside the grid get -1 entries.
        """
        j, i = np.divmod(np.arange(self.rows * self.cols), self.cols)
        shift = j % 2
        corners = [
            (i, j), (i + 1, j), (i + shift, j + 1),  # lower
            (i + 1, j), (i + 1 + shift, j + 1), (i + shift, j + 1),  # upper
        ]
        flat = []
        for ci, cj in corners:
            ok = (ci < self.cols) & (cj < self.rows)
            flat.append(np.where(ok, cj * self.cols + ci, -1))
        lower = np.column_stack(flat[:3])
        upper = np.column_stack(flat[3:])
        return np.stack((lower, upper), axis=1).reshape(-1, 3)

    def locate(self, points: NDArray[np.float64]) -> NDArray[np.int64]:
        """Id of the lattice triangle containing each point, -1 outside the grid."""
        dy = self.h * math.sqrt(3.0) / 2.0
        b = (points[:, 1] - self.origin[1]) / dy
        a = (points[:, 0] - self.origin[0]) / self.h - 0.5 * b
        cell_a = np.floor(a).astype(np.int64)
        cell_b = np.floor(b).astype(np.int64)
        upper = (a - cell_a) + (b - cell_b) >= 1.0
        i = cell_a + cell_b // 2
        inside = (i >= 0) & (i < self.cols) & (cell_b >= 0) & (cell_b < self.rows)
        return np.where(inside, 2 * (cell_b * self.cols + i) + upper, -1)


def _points_for_target(
    curves: tuple[_Curve, ...], target: int
) -> tuple[float, tuple[NDArray[np.float64], ...], _Lattice, NDArray[np.bool_]]:
    """Spacing h, loop arc lengths, lattice and its kept points for about ``target`` vertices.

    The first h solves ``target = D (A - c P h) / h^2 + P / h`` (A area, P perimeter,
    D lattice density, c = _CLEARANCE: the lattice loses a band of width c h along the
    boundary, which carries P / h vertices); then h is rescaled by sqrt(count / target)
    until the count is within _COUNT_TOLERANCE (at most _SPACING_ROUNDS estimates).
    """
    area = abs(sum(c.signed_area for c in curves))
    perimeter = sum(c.length for c in curves)
    a = _LATTICE_DENSITY * area
    b = perimeter * (1.0 - _LATTICE_DENSITY * _CLEARANCE)
    h = 2.0 * a / (-b + math.sqrt(b * b + 4.0 * a * target))  # positive root in 1 / h
    for round_ in range(_SPACING_ROUNDS):
        params = tuple(_resample(c, h) for c in curves)
        loops = [c.at(s) for c, s in zip(curves, params, strict=True)]
        lattice = _Lattice.covering(loops[0].min(axis=0), loops[0].max(axis=0), h)
        valid = _kept_lattice_points(lattice, loops)
        count = sum(len(s) for s in params) + int(np.count_nonzero(valid))
        if abs(count - target) <= _COUNT_TOLERANCE * target or round_ == _SPACING_ROUNDS - 1:
            break
        h *= math.sqrt(count / target)
    return h, params, lattice, valid


def _kept_lattice_points(
    lattice: _Lattice, loops: list[NDArray[np.float64]]
) -> NDArray[np.bool_]:
    """Lattice points inside the domain, >= _CLEARANCE h from it, encroaching on no chord."""
    valid = _inside_domain(lattice.points, loops)
    index = np.flatnonzero(valid)
    distance = _boundary_distance(lattice.points[index], loops, lattice.h, lattice.h)
    index = index[distance >= _CLEARANCE * lattice.h]
    index = index[~_encroaching(lattice.points[index], loops)]
    valid = np.zeros(len(lattice.points), dtype=bool)
    valid[index] = True
    return valid


def _boundary_distance(
    points: NDArray[np.float64], loops: list[NDArray[np.float64]], h: float, upper: float
) -> NDArray[np.float64]:
    """Distance from each point to the loops' chords, over-estimated by at most 0.05 h.

    Uses a k-d tree over a sampling of the chords at spacing <= _SAMPLE_STEP * h (the
    nearest sample is at most half a step from the nearest chord point). Distances above
    ``upper`` (pixels) come back as ``inf``, which keeps the search short far from the
    boundary.
    """
    if len(points) == 0:
        return np.empty(0)
    starts, ends = _chords(loops)
    lengths = np.hypot(*(ends - starts).T)
    counts = np.maximum(1, np.ceil(lengths / (_SAMPLE_STEP * h)).astype(np.int64))
    chord = np.repeat(np.arange(len(starts)), counts)
    t = (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)) / counts[chord]
    samples = starts[chord] + t[:, None] * (ends - starts)[chord]
    distance, _ = cKDTree(samples).query(points, distance_upper_bound=upper)
    return np.asarray(distance, dtype=np.float64)


def _encroaching(
    points: NDArray[np.float64], loops: list[NDArray[np.float64]]
) -> NDArray[np.bool_]:
    """Which points lie inside the diametral circle of some boundary chord."""
    result = np.zeros(len(points), dtype=bool)
    if len(points) == 0:
        return result
    starts, ends = _chords(loops)
    radii = 0.5 * np.hypot(*(ends - starts).T)
    hits = cKDTree(points).query_ball_point(0.5 * (starts + ends), radii)
    result[np.fromiter(itertools.chain.from_iterable(hits), dtype=np.int64)] = True
    return result


def _inside_domain(
    points: NDArray[np.float64], loops: list[NDArray[np.float64]]
) -> NDArray[np.bool_]:
    """Even-odd rule over all loops (inside the outer loop and outside the hole).

    A ray towards +x is cast from each point; an edge counts when
    ``min(y_a, y_b) <= y < max(y_a, y_b)`` and it crosses the ray. Points are sorted by y and
    each edge is paired only with the points in its y range, so the cost is about
    (points x crossings per horizontal line). Points exactly on an edge may go either way.
    """
    starts, ends = _chords(loops)
    slanted = starts[:, 1] != ends[:, 1]
    starts, ends = starts[slanted], ends[slanted]
    y_low = np.minimum(starts[:, 1], ends[:, 1])
    y_high = np.maximum(starts[:, 1], ends[:, 1])
    order = np.argsort(points[:, 1], kind="stable")
    ys = points[order, 1]
    first = np.searchsorted(ys, y_low, side="left")
    counts = np.searchsorted(ys, y_high, side="left") - first
    edge = np.repeat(np.arange(len(starts)), counts)
    rank = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    point = order[first[edge] + rank]
    a, b = starts[edge], ends[edge]
    x_cross = a[:, 0] + (points[point, 1] - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    crossings = np.bincount(point[points[point, 0] < x_cross], minlength=len(points))
    return np.asarray(crossings % 2 == 1)


def _triangulate(
    loops: list[NDArray[np.float64]], lattice: _Lattice, valid: NDArray[np.bool_], h: float
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Core lattice triangles plus Qhull triangles of the band along the boundary.

    Returns the vertices (loops first, then the valid lattice points in flat order), all
    triangles (core first) and the band (Qhull) triangles, counter-clockwise.
    """
    n_boundary = sum(len(loop) for loop in loops)
    index = np.flatnonzero(valid)
    vertices = np.vstack([*loops, lattice.points[index]])
    vertex_of = np.full(len(lattice.points) + 1, -1, dtype=np.int64)  # slot -1 stays -1
    vertex_of[index] = n_boundary + np.arange(len(index))

    distance = np.full(len(lattice.points), np.inf)
    distance[index] = _boundary_distance(
        lattice.points[index], loops, h, (_DEEP + _NEAR_MARGIN) * h
    )
    deep = np.append(valid & (distance >= _DEEP * h), False)  # slot -1: outside the grid
    corners = lattice.triangles()
    is_core = np.all(deep[corners], axis=1)
    core = vertex_of[corners[is_core]]

    near = index[distance[index] < (_DEEP + _NEAR_MARGIN) * h]
    qhull_ids = np.concatenate([np.arange(n_boundary), vertex_of[near]])
    band = _band_triangles(vertices, qhull_ids, loops, h)
    in_core = lattice.locate(vertices[band].mean(axis=1))
    band = band[~((in_core >= 0) & is_core[in_core])]
    return vertices, np.concatenate([core, band]), band


def _band_triangles(
    vertices: NDArray[np.float64],
    ids: NDArray[np.int64],
    loops: list[NDArray[np.float64]],
    h: float,
) -> NDArray[np.int64]:
    """Counter-clockwise Delaunay triangles of ``vertices[ids]`` with centroid in the domain."""
    points = vertices[ids]
    delaunay = Delaunay(points - points.mean(axis=0))
    if delaunay.coplanar.size:
        raise RuntimeError(
            f"internal error: Qhull left {len(delaunay.coplanar)} points out of the "
            "triangulation (duplicate points?)"
        )
    triangles = ids[np.asarray(delaunay.simplices, dtype=np.int64)]
    area = _signed_areas(vertices, triangles)
    triangles = np.where((area < 0)[:, None], triangles[:, [0, 2, 1]], triangles)
    triangles = triangles[np.abs(area) > _DEGENERATE_AREA * h * h]
    centroids = vertices[triangles].mean(axis=1)
    return np.ascontiguousarray(triangles[_inside_domain(centroids, loops)])


def _missing_chords(
    triangles: NDArray[np.int64], sizes: list[int], n_vertices: int
) -> list[NDArray[np.bool_]]:
    """Per loop, which chords (vertex k to k + 1) are not edges of the triangles."""
    edges = _unique_edges(triangles, n_vertices)
    keys = edges[:, 0] * n_vertices + edges[:, 1]
    result = []
    for loop in _loop_indices(sizes):
        following = np.roll(loop, -1)
        chords = np.minimum(loop, following) * n_vertices + np.maximum(loop, following)
        result.append(~_member(chords, keys))
    return result
