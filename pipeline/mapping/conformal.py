"""A discrete conformal map: the honest baseline for CSF-QCM.

The seed paper compares CSF-QCM with Fornberg, Schwarz-Christoffel and Ricci-flow maps. All
three approximate the *conformal* map of the aperture onto the disk or annulus, and wavestack
ships one discrete conformal map in their place, built from harmonic functions on the same mesh:

* **Disk (Riemann map).** With a centre z0 inside the aperture, the Green's function is
  ``G(z) = -log|z - z0| + h(z)`` with h harmonic and ``h = log|z - z0|`` on the boundary; the
  map is ``f(z) = (z - z0) exp(-(h + i h*))`` with h* the harmonic conjugate of h, so
  ``|f| = 1`` on the boundary and f is analytic inside.
* **Annulus.** ``s = log(r_in) u`` with u the harmonic measure (0 outside, 1 on the hole) and
  ``r_in`` the conformal modulus (Eq. 5-7); the angle is the harmonic conjugate of s, periodic
  around the hole; ``w = exp(s + i theta)``.

Conjugates are least-squares fits of ``R90 grad`` (:mod:`wavestack.pipeline.mapping.mesh_calculus`).
The conformal map crowds exponentially along thin parts of an aperture; that is the point of the
comparison, not a defect of this implementation. The centre z0 is the aperture's area centroid
when it lies inside the aperture, otherwise the mesh vertex farthest from the boundary.
"""

from __future__ import annotations

import time

import cv2
import numpy as np
from numpy.typing import NDArray

from .._angles import wrap_angle
from ..aperture import Aperture
from .beltrami import map_quality
from .canonical_map import CanonicalMap, align_rotation, point_inside_hole, vertex_areas
from .laplacian import DirichletSolver, cotangent_laplacian
from .mesh import TriMesh, mesh_aperture
from .mesh_calculus import gradients, least_squares_potential, rotate90
from .modulus import conformal_modulus


def _centre(aperture: Aperture, mesh: TriMesh) -> complex:
    weights = vertex_areas(mesh)
    centroid = (weights @ mesh.vertices) / weights.sum()
    outer = aperture.outer.astype(np.float32).reshape(-1, 1, 2)
    if cv2.pointPolygonTest(outer, (float(centroid[0]), float(centroid[1])), True) > 1.0:
        return complex(centroid[0], centroid[1])
    boundary = mesh.vertices[mesh.boundary_indices]
    interior = mesh.vertices[mesh.interior_indices]
    # distance of each interior vertex to its nearest boundary vertex (chunked)
    best, best_distance = interior[0], -1.0
    for start in range(0, len(interior), 2048):
        chunk = interior[start : start + 2048]
        distance = np.min(np.hypot(*(chunk[:, None, :] - boundary[None, :, :]).transpose(2, 0, 1)), axis=1)
        k = int(np.argmax(distance))
        if distance[k] > best_distance:
            best, best_distance = chunk[k], float(distance[k])
    return complex(best[0], best[1])


def _disk(aperture: Aperture, mesh: TriMesh, stiffness) -> NDArray[np.float64]:
    z = mesh.vertices[:, 0] + 1j * mesh.vertices[:, 1]
    z0 = _centre(aperture, mesh)
    boundary = mesh.boundary_indices
    solver = DirichletSolver(stiffness, boundary)
    h = solver.solve(np.log(np.abs(z[boundary] - z0)))
    field = rotate90(gradients(mesh.vertices, mesh.triangles, h[mesh.triangles]))
    conjugate = least_squares_potential(mesh.vertices, mesh.triangles, stiffness, field)
    f = (z - z0) * np.exp(-(h + 1j * conjugate))
    return np.column_stack([f.real, f.imag])


def _annulus(
    aperture: Aperture, mesh: TriMesh, stiffness
) -> tuple[NDArray[np.float64], float]:
    outer, inner = mesh.boundary_loops
    modulus = conformal_modulus(mesh.vertices, mesh.triangles, outer, inner)
    s = np.log(modulus.r_in) * modulus.harmonic
    hole = point_inside_hole(aperture.hole)
    reference = np.arctan2(mesh.vertices[:, 1] - hole[1], mesh.vertices[:, 0] - hole[0])
    corners = reference[mesh.triangles]
    corners = corners[:, :1] + wrap_angle(corners - corners[:, :1])  # one branch per triangle
    field = rotate90(gradients(mesh.vertices, mesh.triangles, s[mesh.triangles]))
    psi = least_squares_potential(mesh.vertices, mesh.triangles, stiffness, field, corner_offsets=corners)
    theta = reference + psi
    radius = np.exp(s)
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta)]), modulus.r_in


def conformal_map(
    aperture: Aperture, *, target_vertices: int = 15000, mesh: TriMesh | None = None
) -> CanonicalMap:
    """Discrete conformal map of a simply or doubly connected aperture.

    Parameters
    ----------
    aperture : Aperture
    target_vertices : int
        Approximate vertex count of the mesh.
    mesh : TriMesh, optional
        A mesh of the aperture to reuse.

    Returns
    -------
    CanonicalMap

    Raises
    ------
    UnsupportedAperture
        If the aperture is neither simply nor doubly connected.
    """
    timings: dict[str, float] = {}
    tick = time.perf_counter()
    aperture.require_supported()
    mesh = mesh if mesh is not None else mesh_aperture(aperture, target_vertices)
    timings["mesh"] = time.perf_counter() - tick
    tick = time.perf_counter()
    stiffness = cotangent_laplacian(mesh.vertices, mesh.triangles)
    r_in = None
    if len(mesh.boundary_loops) == 1:
        canonical = _disk(aperture, mesh, stiffness)
    else:
        canonical, r_in = _annulus(aperture, mesh, stiffness)
    canonical, rotation = align_rotation(mesh, canonical)
    timings["map"] = time.perf_counter() - tick
    return CanonicalMap(
        mesh=mesh,
        canonical=canonical,
        r_in=r_in,
        kind="conformal",
        laplacian="cotangent",
        quality=map_quality(mesh.vertices, canonical, mesh.triangles),
        rotation_rad=rotation,
        timings=timings,
    )
