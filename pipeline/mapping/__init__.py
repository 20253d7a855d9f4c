"""The CSF-QCM mapping: aperture meshes, Laplacians, curve-shortening flow, conformal modulus,
Beltrami quality, the QCM and conformal canonical maps.
"""

from __future__ import annotations

from .angular_balance import balance_angles
from .annulus_angle import HarmonicAngle, unwrap_loop
from .beltrami import MapQuality, area_scales, beltrami_coefficients, map_quality
from .canonical_map import CanonicalMap, align_rotation, clamp_to_domain, point_inside_hole, vertex_areas
from .conformal import conformal_map
from .csf import CurveFlow, curve_shortening_flow
from .laplacian import LAPLACIANS, DirichletSolver, cotangent_laplacian, graph_laplacian
from .mesh import MAX_TARGET_VERTICES, TriMesh, mesh_aperture
from .mesh_calculus import gradients, hat_gradients, least_squares_potential, rotate90, triangle_areas
from .modulus import (
    ConformalModulus,
    concentric_moebius_parameter,
    concentric_radius_of_circles,
    conformal_modulus,
)
from .pixel_location import PixelLocation, locate_points
from .qcm import csf_qcm_map

__all__ = [
    "CanonicalMap",
    "ConformalModulus",
    "CurveFlow",
    "DirichletSolver",
    "HarmonicAngle",
    "LAPLACIANS",
    "MAX_TARGET_VERTICES",
    "MapQuality",
    "PixelLocation",
    "TriMesh",
    "align_rotation",
    "area_scales",
    "balance_angles",
    "beltrami_coefficients",
    "clamp_to_domain",
    "concentric_moebius_parameter",
    "concentric_radius_of_circles",
    "conformal_map",
    "conformal_modulus",
    "cotangent_laplacian",
    "csf_qcm_map",
    "curve_shortening_flow",
    "gradients",
    "graph_laplacian",
    "hat_gradients",
    "least_squares_potential",
    "locate_points",
    "map_quality",
    "mesh_aperture",
    "point_inside_hole",
    "rotate90",
    "triangle_areas",
    "unwrap_loop",
    "vertex_areas",
]
