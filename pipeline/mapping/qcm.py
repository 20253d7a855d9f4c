"""CSF-guided progressive quasi-conformal map (CSF-QCM) of an aperture onto a disk or annulus.

Yang, Guo, Yang & Xie, "Wavefront fitting over arbitrary freeform apertures via CSF-guided
progressive quasi-conformal mapping" (the seed paper), Algorithm 1:

1. Topology: a simply connected aperture maps to the unit disk; a doubly connected one to the
   annulus ``r_in <= |w| <= 1`` with ``r_in = exp(-2 pi / E)`` from the Dirichlet energy E of its
   harmonic measure (Eq. 5-7, :mod:`wavestack.pipeline.mapping.modulus`).
2. Curve-shortening flow of every boundary loop with arc-length redistribution (Eq. 1-2,
   :mod:`wavestack.pipeline.mapping.csf`). Vertex i of the final, nearly round frame sits at angle
   ``angles[i]``: that is the boundary correspondence.
3. Interior by harmonic relaxation ``L_II P_I = -L_IB P_B`` (Eq. 4), with cotangent weights by
   default or the paper's graph Laplacian (``laplacian="graph"``), factorised once.
4. The Beltrami coefficient (Eq. 3), flips and area scales checked on the result.
5. (wavestack's addition, on by default) angular area balancing
   (:mod:`wavestack.pipeline.mapping.angular_balance`): a monotone reparametrisation of the canonical
   angle so equal sectors hold equal physical area. ``angular_balance=False`` gives the paper's
   method alone.

Where this implementation departs from the paper, and why:

* **The progressive frames do not change the result.** Eq. 4 is linear with a fixed L, so the
  final map depends only on the last frame's boundary positions. The intermediate frames are
  solved (cheaply, with the same factorisation) and their distortion kept as diagnostics
  (``frame_quality``), not because they steer the result.
* **Cotangent weights by default.** The paper uses the graph Laplacian "purely as a numerical
  smoothing operator"; on a Delaunay mesh the cotangent weights are non-negative too (so the
  disk map cannot fold, Tutte/Floater) and they discretise the Dirichlet energy, which makes the
  map converge under refinement. ``laplacian="graph"`` is kept for the paper-faithful mode.
* **Annulus in log-polar form.** A Cartesian harmonic solve into the annulus folds triangles
  next to the hole (the target is not convex). Here ``s = log |w|`` is ``log(r_in)`` times the
  harmonic measure and the angle theta is harmonic with the CSF angles on both loops, solved
  without a seam (:mod:`wavestack.pipeline.mapping.annulus_angle`); the inner loop's rotation relative
  to the outer one minimises the Dirichlet energy of theta. ``(s, theta)`` is an embedding of
  the mesh into a cylinder for non-negative weights, and ``w = exp(s + i theta)`` keeps it one.
* **Rotation** follows the convention of :mod:`wavestack.pipeline.mapping.canonical_map`.
"""

from __future__ import annotations

import logging
import time

import numpy as np
from numpy.typing import NDArray

from .._checks import one_of
from ..aperture import Aperture
from .angular_balance import balance_angles
from .annulus_angle import HarmonicAngle, unwrap_loop
from .beltrami import MapQuality, map_quality
from .canonical_map import CanonicalMap, align_rotation, point_inside_hole, vertex_areas
from .csf import CurveFlow, curve_shortening_flow
from .laplacian import LAPLACIANS, DirichletSolver, cotangent_laplacian, graph_laplacian
from .mesh import TriMesh, mesh_aperture
from .modulus import conformal_modulus

logger = logging.getLogger(__name__)


def _frame_angles(frame: NDArray[np.float64]) -> NDArray[np.float64]:
    """Polar angles of a boundary frame's vertices about its centroid, continuous along it."""
    centre = frame.mean(axis=0)
    return unwrap_loop(np.arctan2(frame[:, 1] - centre[1], frame[:, 0] - centre[0]))


def _laplacian(mesh: TriMesh, laplacian: str):
    one_of(laplacian, "laplacian", LAPLACIANS, voice="expected")
    if laplacian == "graph":
        return graph_laplacian(mesh.triangles, mesh.n_vertices)
    return cotangent_laplacian(mesh.vertices, mesh.triangles)


def _disk_map(
    mesh: TriMesh, solver: DirichletSolver, flow: CurveFlow
) -> tuple[NDArray[np.float64], tuple[MapQuality, ...]]:
    loop = mesh.boundary_loops[0]
    position = {int(v): k for k, v in enumerate(solver.boundary_indices)}
    order = np.array([position[int(v)] for v in loop])

    def solve(angles: NDArray[np.float64]) -> NDArray[np.float64]:
        boundary = np.zeros((len(solver.boundary_indices), 2))
        boundary[order] = np.column_stack([np.cos(angles), np.sin(angles)])
        return solver.solve(boundary)

    frames = tuple(
        map_quality(mesh.vertices, solve(_frame_angles(frame)), mesh.triangles)
        for frame in flow.frames[:-1]
    )
    return solve(flow.angles), frames


def _annulus_map(
    mesh: TriMesh,
    aperture: Aperture,
    laplacian,
    solver: DirichletSolver,
    flows: tuple[CurveFlow, CurveFlow],
    r_in: float,
) -> tuple[NDArray[np.float64], tuple[MapQuality, ...]]:
    outer, inner = mesh.boundary_loops
    angle = HarmonicAngle(mesh.vertices, laplacian, solver, outer, inner, point_inside_hole(aperture.hole))
    log_radius = np.log(r_in) * angle.harmonic_measure

    def solve(outer_angles: NDArray[np.float64], inner_angles: NDArray[np.float64]) -> NDArray[np.float64]:
        theta, _ = angle.solve(outer_angles, inner_angles)
        radius = np.exp(log_radius)
        return np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])

    outer_flow, inner_flow = flows
    frames = []
    for index, frame in enumerate(outer_flow.frames[:-1]):
        inner_frame = inner_flow.frames[min(index, len(inner_flow.frames) - 1)]
        mapped = solve(_frame_angles(frame), _frame_angles(inner_frame))
        frames.append(map_quality(mesh.vertices, mapped, mesh.triangles))
    return solve(outer_flow.angles, inner_flow.angles), tuple(frames)


def csf_qcm_map(
    aperture: Aperture,
    *,
    target_vertices: int = 15000,
    laplacian: str = "cotangent",
    angular_balance: bool = True,
    mesh: TriMesh | None = None,
) -> CanonicalMap:
    """Build the CSF-QCM map of a simply or doubly connected aperture.

    Parameters
    ----------
    aperture : Aperture
        The valid region; several components or several holes raise.
    target_vertices : int
        Approximate vertex count of the mesh (the paper uses about 15k).
    laplacian : {"cotangent", "graph"}
        Weights of the interior harmonic solve (Eq. 4).
    angular_balance : bool
        Apply the angular area balancing after the harmonic solve (see the module notes).
    mesh : TriMesh, optional
        A mesh of the aperture to reuse instead of building one.

    Returns
    -------
    CanonicalMap

    Raises
    ------
    UnsupportedAperture
        If the aperture is neither simply nor doubly connected.
    ValueError
        For an unknown ``laplacian``.
    """
    timings: dict[str, float] = {}
    tick = time.perf_counter()
    aperture.require_supported()
    one_of(laplacian, "laplacian", LAPLACIANS, voice="expected")
    mesh = mesh if mesh is not None else mesh_aperture(aperture, target_vertices)
    timings["mesh"] = time.perf_counter() - tick

    tick = time.perf_counter()
    flows = tuple(curve_shortening_flow(mesh.vertices[loop]) for loop in mesh.boundary_loops)
    timings["csf"] = time.perf_counter() - tick

    tick = time.perf_counter()
    weights = _laplacian(mesh, laplacian)
    solver = DirichletSolver(weights, mesh.boundary_indices)
    timings["factorise"] = time.perf_counter() - tick

    tick = time.perf_counter()
    r_in = None
    if len(mesh.boundary_loops) == 1:
        canonical, frames = _disk_map(mesh, solver, flows[0])
    else:
        outer, inner = mesh.boundary_loops
        r_in = conformal_modulus(mesh.vertices, mesh.triangles, outer, inner).r_in
        canonical, frames = _annulus_map(mesh, aperture, weights, solver, flows, r_in)
    if angular_balance:
        canonical = balance_angles(canonical, vertex_areas(mesh))
    canonical, rotation = align_rotation(mesh, canonical)
    timings["map"] = time.perf_counter() - tick
    quality = map_quality(mesh.vertices, canonical, mesh.triangles)
    logger.info(
        "csf-qcm map: %d vertices, %d flips, max |mu| %.3f, r_in %s",
        mesh.n_vertices, quality.flips, quality.max_beltrami, r_in,
    )
    return CanonicalMap(
        mesh=mesh,
        canonical=canonical,
        r_in=r_in,
        kind="csf-qcm",
        laplacian=laplacian,
        quality=quality,
        frame_quality=frames,
        csf_iterations=flows[0].iterations,
        rotation_rad=rotation,
        timings=timings,
    )
