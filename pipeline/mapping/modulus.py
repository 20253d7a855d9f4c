"""Conformal modulus of a doubly connected domain: the inner radius of its canonical annulus.

A doubly connected domain is conformally equivalent to exactly one annulus
``R_in <= |w| <= 1``. Following section 2.5 of the seed paper (Yang et al., "Wavefront fitting
over arbitrary freeform apertures via CSF-guided progressive quasi-conformal mapping"), ``R_in``
comes from the harmonic measure ``u`` of the inner boundary (Eq. 5), its Dirichlet energy ``E``
(Eq. 6) and ``E = 2 pi / ln(1 / R_in)`` on the annulus (Eq. 7). :func:`concentric_radius_of_circles`
is the closed form for a disk with an off-centre circular hole, used to validate the discretisation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from .laplacian import DirichletSolver, cotangent_laplacian

_MATRIX_RTOL = 1e-12  # a supplied solver's matrix must equal the cotangent Laplacian to rounding


@dataclass(frozen=True)
class ConformalModulus:
    """The canonical annulus of a doubly connected mesh.

    Attributes
    ----------
    r_in : float
        Inner radius of the conformally equivalent annulus ``R_in <= |w| <= 1`` (dimensionless,
        in (0, 1)).
    energy : float
        Dirichlet energy ``E = u^T W u`` of the discrete harmonic measure (dimensionless).
    harmonic : ndarray, shape (V,)
        The discrete harmonic function ``u``: 0 on the outer loop, 1 on the inner loop.
    """

    r_in: float
    energy: float
    harmonic: NDArray[np.float64]


def conformal_modulus(
    vertices: ArrayLike,
    triangles: ArrayLike,
    outer_indices: ArrayLike,
    inner_indices: ArrayLike,
    *,
    solver: DirichletSolver | None = None,
) -> ConformalModulus:
    """Inner radius of the canonical annulus of a doubly connected triangle mesh.

    Solves the discrete Eq. (5) -- ``u`` harmonic for the P1 (cotangent) stiffness matrix
    ``W``, ``u = 0`` on the outer boundary and ``u = 1`` on the inner one -- and returns
    ``E = u^T W u`` (Eq. 6) and ``R_in = exp(-2 pi / E)`` (Eq. 7; on the annulus
    ``u = ln|z| / ln R_in`` has ``E = 2 pi / ln(1 / R_in)``).

    The energy always uses the cotangent stiffness matrix, never the graph Laplacian of Eq. (4):
    only the former's quadratic form discretises ``integral |grad u|^2`` (see
    :func:`~wavestack.pipeline.mapping.laplacian.graph_laplacian`); the paper is explicit about ``W``
    here and we enforce it.

    Accuracy. ``u`` minimises the P1 energy over the continuous piecewise-linear functions with
    the boundary values, so ``E`` is an upper bound of the true energy *of the polygonal mesh
    domain* with an O(h^2) error, and ``R_in`` inherits ``dR/R = ln(1/R) dE/E``. The mesh
    boundary is itself only an approximation of a curved aperture. We take it as given: the
    mesher is expected to put the boundary vertices exactly on the curves, so the loops are
    inscribed polygons -- the outer one lies inside its curve (the domain loses a sliver,
    raising ``E``), the inner one inside the hole (the domain gains a sliver, lowering ``E``);
    both are O(h^2) and the inner one dominates because ``|grad u|`` is largest there. No
    correction is attempted (it would need the exact curves, which this function does not
    receive). Measured for a unit disk with a circular hole, boundary spacing equal to the
    interior spacing (``tests/test_modulus.py``), relative errors in ``R_in`` at ~15k vertices:
    discretisation on the polygon +1.0e-4 to +2.0e-4, inscribed-polygon bias -0.9e-4 to
    -1.8e-4 (both scaling as h^2, i.e. 1/V), net +1e-5 because the two nearly cancel. With a
    boundary much coarser than the interior the bias term dominates; it stays second order.

    Parameters
    ----------
    vertices : array_like, shape (V, 2)
        Physical coordinates (x, y), any length unit (the modulus is scale-invariant).
    triangles : array_like of int, shape (T, 3)
        Counter-clockwise vertex indices.
    outer_indices : array_like of int, shape (B_out,)
        Vertices of the outer boundary loop (any order).
    inner_indices : array_like of int, shape (B_in,)
        Vertices of the inner boundary loop (any order).
    solver : DirichletSolver, optional
        A factorisation to reuse: it must be built on ``cotangent_laplacian(vertices,
        triangles)`` with the outer and inner vertices (in any order) as its boundary.

    Returns
    -------
    ConformalModulus

    Raises
    ------
    ValueError
        If a loop is empty, the loops share a vertex, the mesh is invalid (see
        :func:`~wavestack.pipeline.mapping.laplacian.cotangent_laplacian`), the solver does not match,
        or the energy is not positive (loops not connected through the mesh).

    References
    ----------
    .. [1] Yang et al., seed paper, section 2.5, Eq. (5)-(7).
    .. [2] L. V. Ahlfors, Conformal Invariants, McGraw-Hill (1973), ch. 4 (extremal length of
       the family of curves joining the two boundary components).
    .. [3] H. Hakula, A. Rasila and M. Vuorinen, "On moduli of rings and quadrilaterals:
       algorithms and experiments", SIAM J. Sci. Comput. 33, 279-302 (2011).
    """
    outer = np.asarray(outer_indices, dtype=np.int64).reshape(-1)
    inner = np.asarray(inner_indices, dtype=np.int64).reshape(-1)
    if outer.size == 0 or inner.size == 0:
        raise ValueError("both boundary loops need at least one vertex")
    if np.intersect1d(outer, inner).size:
        raise ValueError("the outer and inner loops share a vertex")
    stiffness = cotangent_laplacian(vertices, triangles)
    boundary = np.concatenate([outer, inner])
    if solver is None:
        solver = DirichletSolver(stiffness, boundary)
    else:
        _check_solver(solver, stiffness, boundary)
    values = np.isin(solver.boundary_indices, inner).astype(np.float64)
    harmonic = solver.solve(values)
    energy = float(harmonic @ (stiffness @ harmonic))
    if not energy > 0.0:
        raise ValueError(f"Dirichlet energy {energy} is not positive; are the loops connected?")
    r_in = math.exp(-2.0 * math.pi / energy)
    return ConformalModulus(r_in=r_in, energy=energy, harmonic=harmonic)


def concentric_moebius_parameter(inner_centre_offset: float, inner_radius: float) -> float:
    """Real ``a`` such that ``z -> (z - a) / (1 - a z)`` maps two circles to concentric ones.

    The outer circle is ``|z| = 1``, the inner one ``|z - d| = r`` with ``d`` real and
    ``|d| + r < 1``. See :func:`concentric_radius_of_circles` for the derivation.

    Parameters
    ----------
    inner_centre_offset : float
        d, the signed distance of the inner centre from the outer centre along the x axis, in
        units of the outer radius.
    inner_radius : float
        r > 0, in units of the outer radius.

    Returns
    -------
    float
        ``a = 2 d / ((1 + d^2 - r^2) + sqrt(Delta))`` in (-1, 1), same sign as d, 0 for d = 0.

    Raises
    ------
    ValueError
        Unless ``r > 0`` and ``|d| + r < 1``.

    References
    ----------
    .. [1] Z. Nehari, Conformal Mapping, McGraw-Hill (1952) (bilinear maps and symmetric
       points); cited as [27] by the seed paper.
    """
    d, r = _checked_circles(inner_centre_offset, inner_radius)
    return 2.0 * d / ((1.0 + d * d - r * r) + math.sqrt(_discriminant(d, r)))


def concentric_radius_of_circles(inner_centre_offset: float, inner_radius: float) -> float:
    """Inner radius ``R_in`` of the annulus conformally equivalent to a disk with a round hole.

    Domain: ``|z| < 1`` minus the closed disk ``|z - d| <= r`` (d real, ``|d| + r < 1``).

    Derivation. For real ``a`` with ``|a| < 1``, ``T(z) = (z - a) / (1 - a z)`` maps the unit
    circle onto itself (for ``|z| = 1``, ``|1 - a z| = |conj(z) - a| = |z - a|``) and the real
    axis onto itself. The inner circle is symmetric about the real axis, so its image is a
    circle centred on the real axis through ``T(d - r)`` and ``T(d + r)``; it is centred at 0
    iff ``T(d - r) = -T(d + r)``. With ``p = d - r`` and ``q = d + r``, clearing denominators
    in ``(p - a)(1 - a q) + (q - a)(1 - a p) = 0`` gives
    ``(p + q) a^2 - 2 (1 + p q) a + (p + q) = 0``, i.e. ::

        d a^2 - (1 + d^2 - r^2) a + d = 0.

    (Equivalently: ``a`` and ``1/a`` are the common symmetric points of both circles.) The
    roots have product 1, so exactly one lies in (-1, 1); written without cancellation,
    ``a = 2 d / ((1 + d^2 - r^2) + sqrt(Delta))`` with
    ``Delta = (1 + d^2 - r^2)^2 - 4 d^2 = ((1 - d)^2 - r^2) ((1 + d)^2 - r^2) > 0``.
    The image annulus is ``R_in < |w| < 1`` with ``R_in = |T(d + r)| = |T(d - r)|``;
    simplifying with the quadratic gives the closed form ::

        R_in = (1 + r^2 - d^2 - sqrt(Delta)) / (2 r) = 2 r / ((1 + r^2 - d^2) + sqrt(Delta)),

    evaluated in the second, cancellation-free form (``(1 + r^2 - d^2)^2 - Delta = 4 r^2``).
    Checks: ``d = 0`` gives ``R_in = r``; ``R_in -> 0`` as ``r -> 0``; ``R_in -> 1`` as the
    gap ``1 - |d| - r -> 0``. The harmonic measure of the inner circle is ``ln|T(z)| / ln R_in``
    with energy ``2 pi / ln(1 / R_in)`` (Eq. 7 of the seed paper).

    Parameters
    ----------
    inner_centre_offset : float
        d, signed offset of the hole's centre, in units of the outer radius (only ``|d|``
        matters).
    inner_radius : float
        r > 0, the hole's radius in units of the outer radius.

    Returns
    -------
    float
        ``R_in`` in (0, 1), dimensionless.

    Raises
    ------
    ValueError
        Unless ``r > 0`` and ``|d| + r < 1``.

    References
    ----------
    .. [1] Z. Nehari, Conformal Mapping, McGraw-Hill (1952), bilinear maps and symmetric points.
    .. [2] Yang et al., seed paper, section 2.5, Eq. (7).
    """
    d, r = _checked_circles(inner_centre_offset, inner_radius)
    return 2.0 * r / ((1.0 + r * r - d * d) + math.sqrt(_discriminant(d, r)))


def _discriminant(d: float, r: float) -> float:
    return ((1.0 - d) ** 2 - r * r) * ((1.0 + d) ** 2 - r * r)


def _checked_circles(d: float, r: float) -> tuple[float, float]:
    d, r = float(d), float(r)
    if not (r > 0.0 and abs(d) + r < 1.0):
        raise ValueError(f"need r > 0 and |d| + r < 1 (hole inside the unit disk): d={d}, r={r}")
    return d, r


def _check_solver(
    solver: DirichletSolver, stiffness: sp.csr_matrix, boundary: NDArray[np.int64]
) -> None:
    if solver.laplacian.shape != stiffness.shape:
        n_mesh = stiffness.shape[0]
        raise ValueError(f"solver is for {solver.n_vertices} vertices, the mesh has {n_mesh}")
    if not np.array_equal(np.sort(solver.boundary_indices), np.sort(boundary)):
        raise ValueError("solver boundary must be exactly the outer and inner loops")
    difference = abs(solver.laplacian - stiffness).max()
    if difference > _MATRIX_RTOL * abs(stiffness).max():
        raise ValueError("solver was not built on the cotangent Laplacian of this mesh")
