"""Distortion of a piecewise-linear map between two triangulations of the same mesh.

A map ``Phi`` from the physical mesh to the canonical one is affine on every triangle, so its
Wirtinger derivatives, its Beltrami coefficient ``mu = f_zbar / f_z`` (Eq. 3 of the seed paper:
Yang et al., "Wavefront fitting over arbitrary freeform apertures via CSF-guided progressive
quasi-conformal mapping") and its area scale ``s = Area(Phi(tau)) / Area(tau)`` (section 3.1.2)
are constant per triangle. :func:`map_quality` condenses them into the monitoring figures of
section 2.4: fold-overs, angular distortion and area uniformity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

_Complex = NDArray[np.complex128]


@dataclass(frozen=True)
class MapQuality:
    """Summary of the distortion of a piecewise-linear map (all fields dimensionless).

    Attributes
    ----------
    flips : int
        Triangles whose image has non-positive signed area (folded or collapsed); 0 for a
        valid orientation-preserving embedding.
    max_beltrami : float
        ``max |mu|`` over the triangles; ``< 1`` iff no triangle is flipped or degenerate,
        ``inf`` if some image triangle is anti-conformal or collapsed to a point.
    p95_beltrami : float
        95th percentile of ``|mu|`` over the triangles (unweighted, empirical quantile).
    area_scale_p5 : float
        5th percentile of the area scale ``s`` *normalised* by the ratio of total areas
        ``sum |Area(Phi(tau))| / sum Area(tau)``, so that a uniform map gives 1 (negative
        values are flipped triangles). ``nan`` if the image has zero total area.
    area_scale_p95 : float
        95th percentile of the same normalised ``s``. ``area_scale_p95 / area_scale_p5`` is
        the scale-free tail spread the seed paper's ECDFs (Fig. 4) show.
    """

    flips: int
    max_beltrami: float
    p95_beltrami: float
    area_scale_p5: float
    area_scale_p95: float


def beltrami_coefficients(
    physical: ArrayLike, canonical: ArrayLike, triangles: ArrayLike
) -> NDArray[np.complex128]:
    """Beltrami coefficient ``mu = f_zbar / f_z`` of the piecewise-affine map, per triangle.

    On triangle ``tau`` the map is ``w = f_z z + f_zbar conj(z) + c``. With Jacobian
    ``[[u_x, u_y], [v_x, v_y]]``, ``f_z = ((u_x + v_y) + i (v_x - u_y)) / 2`` and
    ``f_zbar = ((u_x - v_y) + i (v_x + u_y)) / 2``; they are obtained directly from two edge
    vectors by Cramer's rule: ``dw_k = f_z dz_k + f_zbar conj(dz_k)``, k = 1, 2. The Jacobian
    determinant is ``|f_z|^2 - |f_zbar|^2``, so ``|mu| < 1`` iff the triangle keeps its
    orientation and does not degenerate, ``|mu| = 1`` for a triangle collapsed onto a segment,
    ``|mu| > 1`` for a flipped one.

    Convention where Eq. (3) is undefined (``f_z = 0``): ``mu = inf`` (real). This covers an
    exactly anti-conformal image (a reflection composed with a similarity, ``|mu| = inf``
    being the limit of ``|mu| -> inf`` as ``f_z -> 0``) and a triangle collapsed to a point
    (``f_z = f_zbar = 0``, where no limit exists but the map is certainly not quasiconformal).
    Under a reflection perturbed by rounding, ``|mu|`` is merely huge; either way ``> 1``.

    Parameters
    ----------
    physical : array_like, shape (V, 2)
        Physical vertex coordinates (x, y), any length unit.
    canonical : array_like, shape (V, 2)
        Image of each vertex under the map, any length unit.
    triangles : array_like of int, shape (T, 3)
        Vertex indices, counter-clockwise on the physical mesh.

    Returns
    -------
    ndarray of complex128, shape (T,)
        Dimensionless; 0 for a conformal (similarity) triangle map.

    Raises
    ------
    ValueError
        On wrong shapes, an out-of-range index, non-finite coordinates, or a physical triangle
        with non-positive signed area (the map would be undefined on it).

    References
    ----------
    .. [1] Yang et al., seed paper, section 2.4, Eq. (3).
    .. [2] K. Astala, T. Iwaniec and G. Martin, Elliptic Partial Differential Equations and
       Quasiconformal Mappings in the Plane, Princeton (2009).
    """
    return _beltrami(*_edges(physical, canonical, triangles))


def _beltrami(dz1: _Complex, dz2: _Complex, dw1: _Complex, dw2: _Complex) -> _Complex:
    # [dz1 conj(dz1); dz2 conj(dz2)] [f_z; f_zbar] = [dw1; dw2]; det = -2i cross(dz1, dz2) != 0.
    det = dz1 * np.conj(dz2) - dz2 * np.conj(dz1)
    f_z = (dw1 * np.conj(dz2) - dw2 * np.conj(dz1)) / det
    f_zbar = (dz1 * dw2 - dz2 * dw1) / det
    mu = np.full(f_z.shape, complex(np.inf, 0.0), dtype=np.complex128)
    regular = f_z != 0
    mu[regular] = f_zbar[regular] / f_z[regular]
    return mu


def area_scales(
    physical: ArrayLike, canonical: ArrayLike, triangles: ArrayLike
) -> NDArray[np.float64]:
    """Signed area ratio ``s = Area(Phi(tau)) / Area(tau)`` per triangle (raw, unnormalised).

    This is the discrete Jacobian determinant ``J_Phi`` of sections 2.4 and 3.1.2 of the seed
    paper, except that it keeps the sign: ``s <= 0`` marks a flipped or collapsed triangle
    (the paper's ``|det|`` would hide fold-overs).

    Parameters
    ----------
    physical : array_like, shape (V, 2)
        Physical coordinates, length unit L_p.
    canonical : array_like, shape (V, 2)
        Image coordinates, length unit L_c.
    triangles : array_like of int, shape (T, 3)
        Vertex indices, counter-clockwise on the physical mesh.

    Returns
    -------
    ndarray of float64, shape (T,)
        In units of L_c^2 / L_p^2.

    Raises
    ------
    ValueError
        As :func:`beltrami_coefficients`.

    References
    ----------
    .. [1] Yang et al., seed paper, section 3.1.2 (``s_tau``).
    """
    dz1, dz2, dw1, dw2 = _edges(physical, canonical, triangles)
    return _cross(dw1, dw2) / _cross(dz1, dz2)


def map_quality(physical: ArrayLike, canonical: ArrayLike, triangles: ArrayLike) -> MapQuality:
    """Fold-overs, Beltrami statistics and normalised area-scale percentiles of a map.

    Percentiles are unweighted over triangles (the paper's ECDF, Fig. 4) and use the empirical
    quantile (numpy ``method="inverted_cdf"``: an observed value, no interpolation), which is
    well defined even when some ``|mu|`` are infinite. The area scale is normalised by
    ``sum |Area(Phi(tau))| / sum Area(tau)`` so that any uniform scaling gives 1; the absolute
    values make a pure reflection read -1 rather than be silently un-flipped.

    Parameters
    ----------
    physical : array_like, shape (V, 2)
        Physical coordinates (x, y), any length unit.
    canonical : array_like, shape (V, 2)
        Image coordinates, any length unit.
    triangles : array_like of int, shape (T, 3)
        Vertex indices, counter-clockwise on the physical mesh; T >= 1.

    Returns
    -------
    MapQuality

    Raises
    ------
    ValueError
        As :func:`beltrami_coefficients`, or if there are no triangles.

    References
    ----------
    .. [1] Yang et al., seed paper, section 2.4 (Eq. 3 and area monitoring) and section 3.1.2.
    """
    edges = _edges(physical, canonical, triangles)
    if edges[0].size == 0:
        raise ValueError("no triangles")
    phys_area, image_area = 0.5 * _cross(edges[0], edges[1]), 0.5 * _cross(edges[2], edges[3])
    magnitude = np.abs(_beltrami(*edges))
    total_image = float(np.sum(np.abs(image_area)))
    if total_image > 0.0:
        scale = (image_area / phys_area) / (total_image / float(np.sum(phys_area)))
        s5, s95 = (float(q) for q in np.quantile(scale, [0.05, 0.95], method="inverted_cdf"))
    else:
        s5 = s95 = float("nan")
    return MapQuality(
        flips=int(np.count_nonzero(~(image_area > 0))),
        max_beltrami=float(magnitude.max()),
        p95_beltrami=float(np.quantile(magnitude, 0.95, method="inverted_cdf")),
        area_scale_p5=s5,
        area_scale_p95=s95,
    )


def _edges(
    physical: ArrayLike, canonical: ArrayLike, triangles: ArrayLike
) -> tuple[_Complex, _Complex, _Complex, _Complex]:
    """Complex edge vectors ``dz1, dz2`` (physical) and ``dw1, dw2`` (image) from vertex 0."""
    z = _as_complex(physical, "physical")
    w = _as_complex(canonical, "canonical")
    if w.shape != z.shape:
        raise ValueError(f"canonical has {w.size} vertices, physical {z.size}")
    tris = np.asarray(triangles)
    if tris.ndim != 2 or tris.shape[1] != 3 or not np.issubdtype(tris.dtype, np.integer):
        raise ValueError(f"triangles must be integer (T, 3), got {tris.dtype} {tris.shape}")
    if tris.size and (tris.min() < 0 or tris.max() >= z.size):
        raise ValueError("triangle vertex index out of range")
    zt, wt = z[tris], w[tris]
    dz1, dz2 = zt[:, 1] - zt[:, 0], zt[:, 2] - zt[:, 0]
    if not np.all(_cross(dz1, dz2) > 0):
        raise ValueError("physical triangles must be counter-clockwise with positive area")
    return dz1, dz2, wt[:, 1] - wt[:, 0], wt[:, 2] - wt[:, 0]


def _cross(a: _Complex, b: _Complex) -> NDArray[np.float64]:
    return a.real * b.imag - a.imag * b.real


def _as_complex(points: ArrayLike, name: str) -> _Complex:
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must be (V, 2), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} has non-finite coordinates")
    return array[:, 0] + 1j * array[:, 1]
