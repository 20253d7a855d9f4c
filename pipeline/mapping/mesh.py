"""Triangle mesh of a simply or doubly connected aperture.

The domain mappings (harmonic maps of an aperture onto a disk or an annulus) need a triangle
mesh of the aperture whose boundary follows the aperture polygons and whose interior edges
have non-negative cotangent weights. :func:`mesh_aperture` builds one:

1. every boundary polygon of the :class:`~wavestack.pipeline.aperture.region.Aperture` is resampled
   at near-uniform arc-length spacing ``h``; the resampled vertices lie on the polygon's
   edges, and the polygon's sharp corners (a turn of more than 50 degrees between the chords
   to the points ``max(h, 3 px)`` of arc length before and after) are kept as vertices;
2. the interior gets the points of an equilateral triangular lattice of spacing ``h`` that
   lie inside the domain, at least ``0.7 h`` from the resampled boundary and outside the
   diametral circle of every boundary chord. The clearance was tuned on smooth test
   apertures: the worst minimum angle rises from 18 degrees at 0.4 h to a plateau of
   26-27 degrees between 0.65 h and 0.75 h (nearer points make thin triangles with the
   boundary vertices, farther ones leave wide gaps);
3. lattice triangles whose three vertices lie at least ``1.3 h`` from the boundary ("core")
   are taken as they are: their circumcircle (radius h / sqrt(3)) holds no other point, so
   they are Delaunay triangles. The rest of the domain (the band along the boundary) is
   triangulated by ``scipy.spatial.Delaunay`` (Qhull) of the boundary vertices and the
   lattice points within about 2.5 h of the boundary, keeping the triangles whose centroid
   lies inside the domain and outside the core. This is the Delaunay triangulation of all
   points restricted to the domain, at a fraction of the cost of running Qhull on them all;
4. boundary chords that Delaunay did not recover (narrow gaps) are split at the midpoint of
   their arc on the polygon, the lattice points in the new chords' diametral circles are
   dropped, and the triangulation is repeated. The result is checked: the boundary edges of
   the mesh are exactly the chords of the loops, every point is a vertex and the triangle
   areas add up to the area enclosed by the loops (no overlap, no gap).

Because every kept triangle is a Delaunay triangle, the two angles opposite an interior edge
sum to at most pi, i.e. every interior cotangent weight is non-negative, so harmonic maps
with these weights do not fold. No smoothing is applied: on smooth apertures the minimum
angle is already about 26-32 degrees, and Laplacian sweeps did not raise it measurably.

Coordinates are the project's physical pixel coordinates: ``x = col`` and ``y = -row``.

References
----------
.. [1] J. R. Shewchuk, "Delaunay refinement algorithms for triangular mesh generation",
   Computational Geometry 22(1-3), 21-74 (2002) (conforming boundaries, encroachment).
.. [2] C. B. Barber, D. P. Dobkin and H. Huhdanpaa, "The Quickhull algorithm for convex
   hulls", ACM Trans. Math. Software 22(4), 469-483 (1996) (Qhull behind scipy's Delaunay).
.. [3] M. Meyer, M. Desbrun, P. Schroeder and A. H. Barr, "Discrete differential-geometry
   operators for triangulated 2-manifolds", Visualization and Mathematics III, 35-57 (2003)
   (cotangent weights).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._checks import int_at_least
from ..aperture import Aperture
from .mesh_boundary import _Curve, _loop_indices, _split
from .mesh_geometry import _corner_angles, _member, _polygon_area, _signed_areas, _unique_edges
from .mesh_lattice import _encroaching, _Lattice, _missing_chords, _points_for_target, _triangulate

__all__ = ["MAX_TARGET_VERTICES", "TriMesh", "mesh_aperture"]

logger = logging.getLogger(__name__)

_REPAIR_ROUNDS = 10  # boundary-recovery rounds before giving up
_MIN_TARGET = 16  # smallest accepted target_vertices
# Largest accepted target_vertices: a mesh finer than the pixels adds nothing to a map sampled on
# them, and 10^6 vertices is already the pixel grid of a 1000 x 1000 aperture; the bound stops a
# typo (10^8) before the lattice of that many points is allocated (1.5 GiB at 10^8).
MAX_TARGET_VERTICES = 1_000_000
_AREA_RTOL = 1e-9  # relative tolerance of the check "triangle areas add up to the domain"


@dataclass(frozen=True, eq=False)
class TriMesh:
    """Triangle mesh of an aperture in physical pixel coordinates.

    Attributes
    ----------
    vertices : NDArray[np.float64], shape (V, 2)
        Physical (x, y) in pixels, x = col, y = -row. Read-only. :func:`mesh_aperture` puts
        the vertices of the boundary loops first, in loop order, then the interior vertices.
    triangles : NDArray[np.int64], shape (T, 3)
        Vertex indices, every triangle counter-clockwise (positive signed area). Read-only.
    boundary_loops : tuple of NDArray[np.int64], each shape (n_k,)
        Vertex indices along each boundary loop, first vertex not repeated at the end.
        Loop 0 is the outer boundary, counter-clockwise; loop 1 (doubly connected apertures
        only) is the hole, clockwise. The domain lies on the left when walking either loop.
    spacing : float
        Target edge length ``h`` used, in pixels.
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]
    boundary_loops: tuple[NDArray[np.int64], ...]
    spacing: float

    @property
    def n_vertices(self) -> int:
        """Number of vertices V."""
        return int(self.vertices.shape[0])

    @property
    def boundary_indices(self) -> NDArray[np.int64]:
        """Indices of all boundary vertices, shape (B,): the loops concatenated in order."""
        return np.concatenate(self.boundary_loops).astype(np.int64, copy=False)

    @property
    def interior_indices(self) -> NDArray[np.int64]:
        """Indices of the vertices on no boundary loop, shape (V - B,), increasing."""
        return np.setdiff1d(np.arange(self.n_vertices, dtype=np.int64), self.boundary_indices)

    def triangle_areas(self) -> NDArray[np.float64]:
        """Signed area of every triangle.

        Returns
        -------
        NDArray[np.float64], shape (T,)
            Areas in px^2, positive for counter-clockwise triangles.
        """
        return _signed_areas(self.vertices, self.triangles)

    def min_angle_deg(self) -> float:
        """Smallest interior angle over all triangles.

        Returns
        -------
        float
            Angle in degrees.
        """
        return float(np.degrees(np.min(_corner_angles(self.vertices, self.triangles))))

    def edges(self) -> NDArray[np.int64]:
        """Unique undirected edges.

        Returns
        -------
        NDArray[np.int64], shape (E, 2)
            Vertex index pairs with ``edges[:, 0] < edges[:, 1]``, sorted lexicographically.
        """
        return _unique_edges(self.triangles, self.n_vertices)


def mesh_aperture(aperture: Aperture, target_vertices: int = 15000) -> TriMesh:
    """Triangulate a simply or doubly connected aperture.

    Parameters
    ----------
    aperture : Aperture
        Aperture whose ``outer`` polygon (and ``hole`` polygon, if any) bound the domain,
        in physical pixel coordinates (x = col, y = -row).
    target_vertices : int, optional
        Wanted number of mesh vertices (default 15000); the result is usually within 3 %
        of it. Must be an integer >= 16.

    Returns
    -------
    TriMesh
        Conforming mesh: its boundary edges are exactly the chords of its boundary loops,
        whose vertices lie on the aperture polygons (polygon corners that turn by more than
        50 degrees included); all triangles counter-clockwise; every vertex used; the mesh
        is the restriction of a Delaunay triangulation to the domain (non-negative interior
        cotangent weights). The spacing ``h`` is chosen from the domain area and perimeter
        so that the vertex count is close to ``target_vertices``. The result depends only
        on the aperture and ``target_vertices`` (deterministic).

    Raises
    ------
    UnsupportedAperture
        If the aperture has several components or several holes.
    ValueError
        If ``target_vertices`` is not an integer from 16 to ``MAX_TARGET_VERTICES`` (10^6).
    RuntimeError
        If Delaunay does not recover the boundary after several rounds of splitting the
        missing chords (a gap far narrower than ``h``), or the result fails the conformity
        checks (not expected for apertures from :meth:`Aperture.from_mask`).

    Notes
    -----
    The minimum angle is about 26-32 degrees on smooth apertures. A convex corner of the
    aperture sharper than about 50 degrees, or a gap narrower than about h, gives smaller
    angles there (the corner vertex is kept and Delaunay cannot do better without Steiner
    points that this mesher does not add).

    References
    ----------
    .. [1] J. R. Shewchuk, "Delaunay refinement algorithms for triangular mesh generation",
       Computational Geometry 22(1-3), 21-74 (2002).
    """
    aperture.require_supported()
    target = _validated_target(target_vertices)
    hole = aperture.hole
    polygons = [aperture.outer] if hole is None else [aperture.outer, hole]
    curves = tuple(_Curve.from_polygon(np.asarray(p, dtype=np.float64)) for p in polygons)

    h, params, lattice, valid = _points_for_target(curves, target)
    vertices, triangles, sizes, n_band = _conforming_mesh(curves, params, lattice, valid, h)
    loops = _loop_indices(sizes)
    _check_mesh(vertices, triangles, loops)
    for array in (vertices, triangles, *loops):
        array.flags.writeable = False
    logger.debug(
        "meshed aperture: h=%.4g px, %d vertices (%d on the boundary), %d triangles "
        "(%d from Qhull)",
        h,
        len(vertices),
        sum(sizes),
        len(triangles),
        n_band,
    )
    return TriMesh(vertices=vertices, triangles=triangles, boundary_loops=loops, spacing=h)


def _conforming_mesh(
    curves: tuple[_Curve, ...],
    params: tuple[NDArray[np.float64], ...],
    lattice: _Lattice,
    valid: NDArray[np.bool_],
    h: float,
) -> tuple[NDArray[np.float64], NDArray[np.int64], list[int], int]:
    """Triangulate, splitting boundary chords Delaunay missed until every chord is an edge.

    Returns the vertices, the triangles, the number of vertices of each loop (loops first in
    ``vertices``) and the number of triangles that came from Qhull.
    """
    valid = valid.copy()
    for _ in range(_REPAIR_ROUNDS):
        loops = [c.at(s) for c, s in zip(curves, params, strict=True)]
        vertices, triangles, band = _triangulate(loops, lattice, valid, h)
        sizes = [len(s) for s in params]
        missing = _missing_chords(band, sizes, len(vertices))
        if not any(m.any() for m in missing):
            return vertices, triangles, sizes, len(band)
        logger.debug(
            "splitting %d boundary chords missing from the Delaunay triangulation",
            sum(int(m.sum()) for m in missing),
        )
        params = tuple(
            _split(s, m, c.length) for c, s, m in zip(curves, params, missing, strict=True)
        )
        loops = [c.at(s) for c, s in zip(curves, params, strict=True)]
        valid &= ~_encroaching(lattice.points, loops)
    raise RuntimeError(
        f"Delaunay triangulation did not recover the aperture boundary after "
        f"{_REPAIR_ROUNDS} rounds of splitting boundary chords (spacing h = {h:.4g} px); "
        "the aperture may have a gap much narrower than h - try a larger target_vertices"
    )


# ----------------------------------------------------------------------------- triangulation


def _check_mesh(
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    loops: tuple[NDArray[np.int64], ...],
) -> None:
    """Raise RuntimeError unless the mesh conforms to its loops and tiles their domain.

    Checks: the boundary half-edges of the triangles (those whose reverse is not a
    half-edge) are exactly the directed chords of the loops; every vertex is used; every
    triangle is counter-clockwise and their areas add up to the area the loops enclose.
    """
    n = len(vertices)
    half = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    forward = half[:, 0] * n + half[:, 1]
    backward = half[:, 1] * n + half[:, 0]
    boundary = np.sort(forward[~_member(forward, np.sort(backward))])
    expected = np.sort(np.concatenate([loop * n + np.roll(loop, -1) for loop in loops]))
    if boundary.shape != expected.shape or np.any(boundary != expected):
        raise RuntimeError(
            f"internal error: the mesh has {len(boundary)} boundary half-edges and the loops "
            f"{len(expected)} chords, and they differ"
        )
    used = np.zeros(n, dtype=bool)
    used[triangles.ravel()] = True
    if not used.all():
        raise RuntimeError(f"internal error: {n - int(used.sum())} of {n} points in no triangle")
    areas = _signed_areas(vertices, triangles)
    domain = sum(_polygon_area(vertices[loop]) for loop in loops)
    if np.any(areas <= 0) or abs(areas.sum() - domain) > _AREA_RTOL * domain:
        raise RuntimeError(
            f"internal error: triangle areas add up to {areas.sum():.12g} px^2 but the "
            f"boundary loops enclose {domain:.12g} px^2 (or a triangle is not counter-clockwise)"
        )


# ----------------------------------------------------------------------------- small helpers


def _validated_target(target_vertices: int) -> int:
    """Check ``target_vertices`` (16 to ``MAX_TARGET_VERTICES``) and return it as an int."""
    target = int_at_least(target_vertices, "target_vertices", _MIN_TARGET, voice="is")
    if target > MAX_TARGET_VERTICES:
        raise ValueError(f"target_vertices is {target}; expected at most {MAX_TARGET_VERTICES} "
                         "(a mesh finer than the pixels adds nothing)")
    return target
