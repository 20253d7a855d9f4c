"""What every aperture-to-canonical-domain map shares: its result, rotation and sampling.

A map sends the vertices of a triangle mesh of the aperture to the unit disk (simply connected
aperture) or to the annulus ``r_in <= |w| <= 1`` (doubly connected); it is piecewise linear on
the triangles. Two things are fixed here for every construction:

* **Rotation convention.** A map to the disk or annulus is only defined up to a rotation (it
  depends on where a contour happens to start). wavestack rotates every map so that canonical
  coordinates line up with physical ones in the least-squares sense: the rotation alpha
  maximises ``sum_i a_i Re(exp(i alpha) w_i conj(z_i - c))`` over the mesh vertices, with
  ``a_i`` the vertex areas, ``z_i`` the physical positions and ``c`` the aperture centroid
  (an orthogonal Procrustes fit). The same aperture then always gives the same coefficients,
  and an aperture rotated by beta gives a map, and coefficients, rotated by beta.
* **Sampling.** Pixel centres are located in the mesh once per aperture; their canonical
  coordinates are a sparse matrix of barycentric weights times the vertex images. Centres that
  fall just outside the mesh (the boundary polygon is an approximation of the pixel edge) are
  extrapolated from the nearest triangle and clamped into the canonical domain.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from .beltrami import MapQuality
from .mesh import TriMesh
from .mesh_calculus import triangle_areas
from .pixel_location import locate_points

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class CanonicalMap:
    """A piecewise-linear map of an aperture mesh onto the unit disk or a concentric annulus.

    Attributes
    ----------
    mesh : TriMesh
        The physical mesh (pixels, x = col, y = -row).
    canonical : ndarray, shape (V, 2)
        Image of every mesh vertex, in unit-disk coordinates.
    r_in : float or None
        Inner radius of the canonical annulus; None for the disk.
    kind : str
        "csf-qcm" or "conformal".
    laplacian : str
        Weights of the interior solve: "cotangent" or "graph".
    quality : MapQuality
        Flips, Beltrami coefficient and area-scale statistics of the final map.
    frame_quality : tuple of MapQuality
        The same for each progressive frame (CSF-QCM only; diagnostics).
    csf_iterations : int or None
        Iterations of the curve-shortening flow (the outer loop's), None without CSF.
    rotation_rad : float
        Rotation applied by the rotation convention, radians.
    timings : mapping of str to float
        Seconds per stage.
    """

    mesh: TriMesh
    canonical: NDArray[np.float64]
    r_in: float | None
    kind: str
    laplacian: str
    quality: MapQuality
    frame_quality: tuple[MapQuality, ...] = ()
    csf_iterations: int | None = None
    rotation_rad: float = 0.0
    timings: Mapping[str, float] = field(default_factory=dict)

    def map_points(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        """Canonical coordinates of physical points.

        Parameters
        ----------
        x, y : ndarray, shape (N,)
            Physical coordinates in pixels (x = col, y = -row).

        Returns
        -------
        ndarray, shape (N, 2)
            Points in the canonical disk or annulus (clamped into it).
        """
        location = locate_points(self.mesh, x, y)
        mapped = location.weights @ self.canonical
        if np.any(location.outside):
            logger.debug("%d points outside the mesh extrapolated", int(location.outside.sum()))
        return clamp_to_domain(mapped, self.r_in)


def clamp_to_domain(points: NDArray[np.float64], r_in: float | None) -> NDArray[np.float64]:
    """Move points radially into the disk ``|w| <= 1`` or the annulus ``r_in <= |w| <= 1``.

    Parameters
    ----------
    points : ndarray, shape (N, 2)
    r_in : float or None

    Returns
    -------
    ndarray, shape (N, 2)
    """
    radius = np.hypot(points[:, 0], points[:, 1])
    target = np.clip(radius, 0.0 if r_in is None else r_in, 1.0)
    scale = np.divide(target, radius, out=np.ones_like(radius), where=radius > 0)
    return points * scale[:, None]


def vertex_areas(mesh: TriMesh) -> NDArray[np.float64]:
    """Lumped vertex areas: a third of the area of every adjacent triangle, shape (V,)."""
    areas = triangle_areas(mesh.vertices, mesh.triangles)
    return np.bincount(mesh.triangles.ravel(), weights=np.repeat(areas / 3.0, 3), minlength=mesh.n_vertices)


def align_rotation(
    mesh: TriMesh, canonical: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float]:
    """Rotate a canonical map to the rotation convention (area-weighted Procrustes).

    Parameters
    ----------
    mesh : TriMesh
    canonical : ndarray, shape (V, 2)

    Returns
    -------
    rotated : ndarray, shape (V, 2)
    angle : float
        The rotation applied, radians counter-clockwise.
    """
    weights = vertex_areas(mesh)
    physical = mesh.vertices[:, 0] + 1j * mesh.vertices[:, 1]
    centre = np.sum(weights * physical) / np.sum(weights)
    image = canonical[:, 0] + 1j * canonical[:, 1]
    angle = float(np.angle(np.sum(weights * np.conj(image) * (physical - centre))))
    rotated = image * np.exp(1j * angle)
    return np.column_stack([rotated.real, rotated.imag]), angle


def point_inside_hole(hole: NDArray[np.float64]) -> tuple[float, float]:
    """A point well inside a hole polygon: the grid point farthest from its boundary.

    Used as the centre of the reference angle of a doubly connected aperture; it must lie
    inside the hole (a triangular or crescent hole's vertex average may not).

    Parameters
    ----------
    hole : ndarray, shape (K, 2)

    Returns
    -------
    (x, y) : tuple of float
    """
    contour = hole.astype(np.float32).reshape(-1, 1, 2)
    low, high = hole.min(axis=0), hole.max(axis=0)
    best, best_distance = tuple(hole.mean(axis=0)), -np.inf
    for gx in np.linspace(low[0], high[0], 33):
        for gy in np.linspace(low[1], high[1], 33):
            distance = cv2.pointPolygonTest(contour, (float(gx), float(gy)), True)
            if distance > best_distance:
                best, best_distance = (float(gx), float(gy)), distance
    if best_distance <= 0:
        raise ValueError("hole: no interior point found; expected a hole with a positive area")
    return best
