"""Barycentric weights of points (pixel centres) in a triangle mesh of the aperture.

A map defined at the mesh vertices is carried to arbitrary points by linear interpolation in
the triangle that holds each point. :func:`locate_points` finds that triangle and the
barycentric weights once per aperture, as a sparse (N, V) matrix ``W`` so that any vertex
field ``f`` (shape (V,) or (V, k)) interpolates as ``W @ f``.

Point location uses a uniform bucket grid: every triangle is registered in the grid cells its
bounding box overlaps (cells of about a third of the mesh spacing, so a cell meets about four
triangles) and each point is tested, by its barycentric coordinates, against the triangles of
its cell, one candidate per vectorised round, until one holds it. This is exact up to a
tolerance of 1e-12 in the barycentric coordinates (points on an edge go to the first triangle
tested), works for any mesh (no Delaunay assumption) and its cost is linear in the number of
points. Points that no triangle holds (outside the mesh, e.g. pixel centres in the thin strip
between the polygonal mesh boundary and the pixel edge) get the triangle of the nearest
boundary edge, with extrapolated barycentric coordinates (some negative) that still reproduce
the point exactly; callers clamp the mapped points into their canonical domain.

References
----------
.. [1] J. L. Bentley and J. H. Friedman, "Data structures for range searching", ACM Computing
   Surveys 11(4), 397-409 (1979) (cell / bucket methods).
.. [2] M. de Berg, O. Cheong, M. van Kreveld and M. Overmars, Computational Geometry:
   Algorithms and Applications, 3rd ed., Springer (2008), ch. 6 (point location).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .mesh import TriMesh

__all__ = ["PixelLocation", "locate_points"]

logger = logging.getLogger(__name__)

_CELL_FACTOR = 0.5  # grid cell side in units of sqrt(mean triangle area) (~ h / 3)
_MAX_CELLS = 1 << 24  # upper bound on the number of grid cells (memory guard)
_BARY_TOL = 1e-12  # barycentric coordinates >= -tol count as inside the triangle
_NEAREST_VERTICES = 8  # boundary vertices whose incident edges are tried for outside points


@dataclass(frozen=True, eq=False)
class PixelLocation:
    """Where points lie in a mesh, as barycentric interpolation weights.

    Attributes
    ----------
    weights : scipy.sparse.csr_matrix, shape (N, V)
        Row i holds the barycentric weights of point i with respect to the three vertices of
        ``triangle[i]`` (three stored entries per row, columns increasing, summing to 1;
        an entry can be an explicit 0 for a point on an edge or at a vertex). Inside points
        have weights in [0, 1]; outside points have extrapolated weights, some negative.
        ``weights @ mesh.vertices`` reproduces the points.
    triangle : NDArray[np.int64], shape (N,)
        Index into ``mesh.triangles`` of the triangle holding each point, or for outside
        points the triangle of the nearest boundary edge.
    outside : NDArray[np.bool_], shape (N,)
        True where no triangle holds the point (weights extrapolated).
    """

    weights: scipy.sparse.csr_matrix
    triangle: NDArray[np.int64]
    outside: NDArray[np.bool_]


def locate_points(mesh: TriMesh, x: ArrayLike, y: ArrayLike) -> PixelLocation:
    """Barycentric weights of points in a triangle mesh.

    Parameters
    ----------
    mesh : TriMesh
        Mesh with counter-clockwise triangles and boundary loops that have the domain on
        their left (as built by :func:`~wavestack.pipeline.mapping.mesh.mesh_aperture`).
    x, y : array_like, same shape (any; flattened in C order to N points)
        Physical coordinates in pixels (x = col, y = -row), finite.

    Returns
    -------
    PixelLocation
        Sparse (N, V) weights, containing (or nearest) triangle and outside flags. For an
        outside point the triangle is the one on the nearest boundary edge among the edges
        incident to its 8 nearest boundary vertices (the true nearest edge except for points
        far from a strongly non-convex boundary, where any close edge serves extrapolation).

    Raises
    ------
    ValueError
        If ``x`` and ``y`` differ in shape or hold non-finite values, or the mesh has no
        triangle, or (checked when some point is outside) its boundary loops are not edges
        of its counter-clockwise triangles with the domain on their left.

    Notes
    -----
    Cost: linear in N plus building the grid, about 0.2 s for 6.3e5 points and a
    15k-vertex mesh (2-core CI machine); most points need a single barycentric test.

    References
    ----------
    .. [1] M. de Berg, O. Cheong, M. van Kreveld and M. Overmars, Computational Geometry:
       Algorithms and Applications, 3rd ed., Springer (2008), ch. 6.
    """
    px, py = _validated_points(x, y)
    if len(mesh.triangles) == 0:
        raise ValueError("mesh has no triangle; cannot locate points")
    frame = _TriangleFrames.of(mesh)
    triangle, bary = _BucketGrid.of(mesh, frame).locate(px, py, frame)
    outside = triangle < 0
    if outside.any():
        ox, oy = px[outside], py[outside]
        nearest = _nearest_boundary_triangle(mesh, np.column_stack((ox, oy)))
        triangle[outside] = nearest
        bary[outside] = frame.barycentric(ox, oy, nearest)
        logger.debug("%d of %d points outside the mesh, extrapolated", outside.sum(), len(px))
    rounded = np.flatnonzero(~outside & (bary.min(axis=1) < 0.0))  # -1e-12 <= l < 0 on edges
    clipped = np.maximum(bary[rounded], 0.0)
    bary[rounded] = clipped / clipped.sum(axis=1, keepdims=True)

    n = len(px)
    weights = scipy.sparse.csr_matrix(
        (bary.ravel(), mesh.triangles[triangle].ravel(), np.arange(0, 3 * n + 1, 3)),
        shape=(n, mesh.n_vertices),
    )
    weights.sort_indices()
    return PixelLocation(weights=weights, triangle=triangle, outside=outside)


@dataclass(frozen=True, eq=False)
class _TriangleFrames:
    """Per triangle, the affine map from a point to its barycentric coordinates 1 and 2.

    ``l1 = a (x - x0) + b (y - y0)`` and ``l2 = c (x - x0) + d (y - y0)``, where (x0, y0) is
    the first vertex and [[a, b], [c, d]] the inverse of the matrix whose columns are the
    edge vectors v1 - v0 and v2 - v0; coordinate 0 is ``1 - l1 - l2``. Each is a separate
    contiguous (T,) array: gathering them per candidate is the inner loop of the search.
    """

    x0: NDArray[np.float64]
    y0: NDArray[np.float64]
    a: NDArray[np.float64]
    b: NDArray[np.float64]
    c: NDArray[np.float64]
    d: NDArray[np.float64]

    @classmethod
    def of(cls, mesh: TriMesh) -> _TriangleFrames:
        v = mesh.vertices[mesh.triangles]
        e1 = v[:, 1] - v[:, 0]
        e2 = v[:, 2] - v[:, 0]
        det = _cross(e1, e2)
        return cls(
            x0=np.ascontiguousarray(v[:, 0, 0]),
            y0=np.ascontiguousarray(v[:, 0, 1]),
            a=e2[:, 1] / det,
            b=-e2[:, 0] / det,
            c=-e1[:, 1] / det,
            d=e1[:, 0] / det,
        )

    @property
    def areas(self) -> NDArray[np.float64]:
        """Absolute triangle areas, shape (T,) (from the inverse's determinant)."""
        return 0.5 / np.abs(self.a * self.d - self.b * self.c)

    def coordinates(
        self, x: NDArray[np.float64], y: NDArray[np.float64], tri: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Barycentric coordinates 1 and 2 of points (x, y) in triangles ``tri``
        (extrapolated outside them)."""
        dx = x - self.x0[tri]
        dy = y - self.y0[tri]
        return dx * self.a[tri] + dy * self.b[tri], dx * self.c[tri] + dy * self.d[tri]

    def barycentric(
        self, x: NDArray[np.float64], y: NDArray[np.float64], tri: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Barycentric coordinates (N, 3) of points (x, y) in triangles ``tri``."""
        l1, l2 = self.coordinates(x, y, tri)
        return np.column_stack((1.0 - l1 - l2, l1, l2))


@dataclass(frozen=True, eq=False)
class _BucketGrid:
    """Uniform grid whose cells list the triangles their bounding boxes overlap.

    ``members[start[c]:start[c + 1]]`` are the triangles registered in cell ``c``
    (row-major, ``ny`` rows of ``nx`` cells of side ``size`` from ``corner``); the triangle
    that holds the cell centre, if any, comes first, so most points need one test.
    """

    corner: tuple[float, float]
    size: float
    nx: int
    ny: int
    start: NDArray[np.int64]
    members: NDArray[np.int64]

    @classmethod
    def of(cls, mesh: TriMesh, frame: _TriangleFrames) -> _BucketGrid:
        v = mesh.vertices[mesh.triangles]
        low = v.min(axis=1)
        high = v.max(axis=1)
        corner = low.min(axis=0)
        extent = high.max(axis=0) - corner
        mean_area = float(frame.areas.mean())
        size = _CELL_FACTOR * math.sqrt(mean_area)
        size = max(size, math.sqrt((extent[0] + 1.0) * (extent[1] + 1.0) / _MAX_CELLS))
        # Same floor((coordinate - corner) / size) as for the cells of points and boxes.
        nx = int(np.floor(extent[0] / size)) + 1
        ny = int(np.floor(extent[1] / size)) + 1
        first = np.floor((low - corner) / size).astype(np.int64)
        last = np.floor((high - corner) / size).astype(np.int64)
        width = last[:, 0] - first[:, 0] + 1
        counts = width * (last[:, 1] - first[:, 1] + 1)
        tri = np.repeat(np.arange(len(v)), counts)
        k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        row, col = np.divmod(k, width[tri])
        row += first[tri, 1]
        col += first[tri, 0]
        l1, l2 = frame.coordinates(
            corner[0] + size * (col + 0.5), corner[1] + size * (row + 0.5), tri
        )
        holds_centre = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
        cells = row * nx + col
        order = np.argsort(2 * cells + ~holds_centre, kind="stable")
        start = np.concatenate(([0], np.cumsum(np.bincount(cells, minlength=nx * ny))))
        return cls(
            corner=(float(corner[0]), float(corner[1])),
            size=size,
            nx=nx,
            ny=ny,
            start=start,
            members=tri[order],
        )

    def locate(
        self, x: NDArray[np.float64], y: NDArray[np.float64], frame: _TriangleFrames
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Index of the triangle holding each point (-1 if none does) and the barycentric
        coordinates (N, 3) in it (zeros for the points no triangle holds)."""
        triangle = np.full(len(x), -1, dtype=np.int64)
        bary = np.zeros((len(x), 3))
        ix = np.floor((x - self.corner[0]) / self.size)
        iy = np.floor((y - self.corner[1]) / self.size)
        active = np.flatnonzero((ix >= 0) & (ix < self.nx) & (iy >= 0) & (iy < self.ny))
        cell = iy[active].astype(np.int64) * self.nx + ix[active].astype(np.int64)
        first = self.start[cell]
        count = self.start[cell + 1] - first
        rank = 0
        while active.size:
            keep = count > rank
            active, first, count = active[keep], first[keep], count[keep]
            candidate = self.members[first + rank]
            l1, l2 = frame.coordinates(x[active], y[active], candidate)
            hit = (l1 >= -_BARY_TOL) & (l2 >= -_BARY_TOL) & (l1 + l2 <= 1.0 + _BARY_TOL)
            found = active[hit]
            triangle[found] = candidate[hit]
            bary[found, 1] = l1[hit]
            bary[found, 2] = l2[hit]
            miss = ~hit
            active, first, count = active[miss], first[miss], count[miss]
            rank += 1
        bary[:, 0] = 1.0 - bary[:, 1] - bary[:, 2]
        return triangle, bary


def _nearest_boundary_triangle(
    mesh: TriMesh, points: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Triangle on the nearest boundary edge of each point (N, 2), among the edges incident
    to its _NEAREST_VERTICES nearest boundary vertices."""
    loops = mesh.boundary_loops
    starts = np.concatenate(loops)
    ends = np.concatenate([np.roll(loop, -1) for loop in loops])
    # Position of each boundary vertex's incoming edge (edges are indexed like `starts`).
    sizes = np.array([len(loop) for loop in loops])
    offsets = np.repeat(np.cumsum(sizes) - sizes, sizes)
    local = np.arange(len(starts)) - offsets
    incoming = offsets + (local - 1) % np.repeat(sizes, sizes)
    edge_triangle = _half_edge_triangles(mesh, starts, ends)

    k = min(_NEAREST_VERTICES, len(starts))
    _, near = cKDTree(mesh.vertices[starts]).query(points, k=k)
    near = np.asarray(near, dtype=np.int64).reshape(len(points), k)
    edges = np.concatenate([near, incoming[near]], axis=1)  # outgoing edge has the same index
    a = mesh.vertices[starts[edges]]
    b = mesh.vertices[ends[edges]]
    ab = b - a
    ap = points[:, None, :] - a
    t = np.clip(np.sum(ap * ab, axis=2) / np.sum(ab * ab, axis=2), 0.0, 1.0)
    gap = ap - t[..., None] * ab
    best = np.argmin(np.sum(gap * gap, axis=2), axis=1)
    return edge_triangle[edges[np.arange(len(points)), best]]


def _half_edge_triangles(
    mesh: TriMesh, starts: NDArray[np.int64], ends: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Index of the triangle holding each directed edge ``starts[i] -> ends[i]``."""
    n = mesh.n_vertices
    t = mesh.triangles.astype(np.int64)
    keys = np.concatenate([t[:, 0] * n + t[:, 1], t[:, 1] * n + t[:, 2], t[:, 2] * n + t[:, 0]])
    owner = np.tile(np.arange(len(t)), 3)
    order = np.argsort(keys, kind="stable")
    keys, owner = keys[order], owner[order]
    wanted = starts * n + ends
    position = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
    found = keys[position] == wanted
    if not found.all():
        raise ValueError(
            f"{int((~found).sum())} boundary-loop edges are not counter-clockwise triangle "
            "edges of the mesh (loops must have the domain on their left)"
        )
    return owner[position]


def _validated_points(
    x: ArrayLike, y: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """x and y as flattened contiguous float64 arrays, each shape (N,), after checks."""
    xs = np.asarray(x, dtype=np.float64)
    ys = np.asarray(y, dtype=np.float64)
    if xs.shape != ys.shape:
        raise ValueError(
            f"x has shape {xs.shape} but y has shape {ys.shape}; expected equal shapes"
        )
    xs = np.ascontiguousarray(xs.ravel())
    ys = np.ascontiguousarray(ys.ravel())
    bad = ~(np.isfinite(xs) & np.isfinite(ys))
    if bad.any():
        raise ValueError(
            f"{int(bad.sum())} points have NaN or infinite coordinates; expected finite x, y"
        )
    return xs, ys


def _cross(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """z component of the cross product of the rows of two (N, 2) arrays."""
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
