"""The angular coordinate of a doubly connected aperture, without cutting the mesh.

On an annulus the canonical angle theta is multivalued: it grows by 2 pi around the hole. Rather
than cutting the mesh along a seam, theta is written as ``theta = theta0 + psi`` where
``theta0(z) = arg(z - z_h)`` is a known function with the same period (z_h a point inside the
hole) and psi is single-valued. Along every mesh edge the difference of theta0 is taken as the
principal value of the angle difference, which is exact for edges much shorter than their
distance to z_h. A harmonic theta with weights w_ij then means, at every interior vertex,
``sum_j w_ij (d_ij + psi_i - psi_j) = 0``: a Laplace problem for psi with a known right-hand
side. The map ``w = exp(s + i theta)`` only needs ``exp(i theta)``, so the branch of theta0 at a
vertex never matters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
from numpy.typing import NDArray

from .._angles import wrap_angle
from .laplacian import DirichletSolver


def unwrap_loop(angles: NDArray[np.float64]) -> NDArray[np.float64]:
    """Make angles continuous along a loop (steps of at most pi), keeping the first value."""
    return angles[0] + np.concatenate([[0.0], np.cumsum(wrap_angle(np.diff(angles)))])


@dataclass(frozen=True)
class _EdgeWeights:
    rows: NDArray[np.int64]
    cols: NDArray[np.int64]
    weights: NDArray[np.float64]


def _edge_weights(laplacian: scipy.sparse.spmatrix) -> _EdgeWeights:
    coo = scipy.sparse.coo_matrix(laplacian)
    off = coo.row != coo.col
    return _EdgeWeights(coo.row[off], coo.col[off], -coo.data[off])


class HarmonicAngle:
    """Solves for a harmonic angle with prescribed boundary angles on both loops.

    Parameters
    ----------
    vertices : ndarray, shape (V, 2)
        Physical mesh vertices.
    laplacian : sparse matrix, shape (V, V)
        Weights of the harmonic condition (cotangent or graph Laplacian).
    solver : DirichletSolver
        Factorisation of ``laplacian`` with both boundary loops fixed.
    outer, inner : ndarray of int
        Vertex indices of the two loops, in order.
    hole_point : (x, y)
        A point inside the hole, centre of the reference angle theta0.
    """

    def __init__(
        self,
        vertices: NDArray[np.float64],
        laplacian: scipy.sparse.spmatrix,
        solver: DirichletSolver,
        outer: NDArray[np.int64],
        inner: NDArray[np.int64],
        hole_point: tuple[float, float],
    ) -> None:
        self._solver = solver
        self._outer, self._inner = outer, inner
        self.reference = np.arctan2(vertices[:, 1] - hole_point[1], vertices[:, 0] - hole_point[0])
        edges = _edge_weights(laplacian)
        self._edges = edges
        self._differences = wrap_angle(self.reference[edges.rows] - self.reference[edges.cols])
        rhs = -np.bincount(edges.rows, weights=edges.weights * self._differences, minlength=len(vertices))
        self._interior_rhs = rhs[solver.interior_indices]
        # psi for inner boundary value 1, outer 0: the harmonic measure of these weights.
        self.harmonic_measure = self._solve_psi(np.zeros(len(outer)), np.ones(len(inner)), rhs=False)

    def _boundary_values(self, outer_values: NDArray, inner_values: NDArray) -> NDArray[np.float64]:
        values = np.zeros(len(self._solver.boundary_indices))
        position = {int(v): k for k, v in enumerate(self._solver.boundary_indices)}
        values[[position[int(v)] for v in self._outer]] = outer_values
        values[[position[int(v)] for v in self._inner]] = inner_values
        return values

    def _solve_psi(self, outer_values: NDArray, inner_values: NDArray, rhs: bool) -> NDArray[np.float64]:
        return self._solver.solve(
            self._boundary_values(outer_values, inner_values),
            self._interior_rhs if rhs else None,
        )

    def _psi_on_loop(self, loop: NDArray[np.int64], angles: NDArray[np.float64]) -> NDArray[np.float64]:
        """Boundary psi = theta - theta0 along a loop, both made continuous along it."""
        psi = unwrap_loop(angles) - unwrap_loop(self.reference[loop])
        return psi - 2.0 * np.pi * np.round(np.mean(psi) / (2.0 * np.pi))

    def energy(self, psi: NDArray[np.float64]) -> float:
        """Dirichlet energy ``sum_edges w_ij (theta_i - theta_j)^2`` of theta = theta0 + psi."""
        e = self._edges
        step = self._differences + psi[e.rows] - psi[e.cols]
        return 0.5 * float(np.sum(e.weights * step * step))

    def solve(
        self, outer_angles: NDArray[np.float64], inner_angles: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float]:
        """Harmonic theta for boundary angles, with the inner loop's rotation chosen freely.

        The inner loop's angles are shifted by the rotation phi that minimises the Dirichlet
        energy of theta; the energy is quadratic in phi (``psi = psi0 + phi * h`` with h the
        harmonic measure), so phi has a closed form.

        Parameters
        ----------
        outer_angles, inner_angles : ndarray
            Target angles of the loops' vertices (radians), continuous along each loop.

        Returns
        -------
        theta : ndarray, shape (V,)
            ``theta0 + psi``, to be used through ``exp(i theta)``.
        phi : float
            The inner loop's rotation, radians.
        """
        base = self._solve_psi(
            self._psi_on_loop(self._outer, outer_angles),
            self._psi_on_loop(self._inner, inner_angles),
            rhs=True,
        )
        e, h = self._edges, self.harmonic_measure
        step_base = self._differences + base[e.rows] - base[e.cols]
        step_h = h[e.rows] - h[e.cols]
        phi = -float(np.sum(e.weights * step_base * step_h) / np.sum(e.weights * step_h * step_h))
        psi = base + phi * h
        return self.reference + psi, phi
