"""Calculus on a triangle mesh: gradients of piecewise-linear functions and their conjugates.

A piecewise-linear (P1) function is given by its values at the vertices; on each triangle its
gradient is constant. For a counter-clockwise triangle (p0, p1, p2) of area A, the gradient of
the hat function of vertex i is ``R90 (p[i+2] - p[i+1]) / (2 A)`` with ``R90 (x, y) = (-y, x)``.

The harmonic conjugate of a harmonic function h is the function h* whose gradient is
``R90 grad h`` (Cauchy-Riemann). On a mesh ``R90 grad h`` is only approximately a gradient, so
h* is taken as the least-squares fit ``min sum_T A_T |grad h*_T - R90 grad h_T|^2``, whose normal
equations are the cotangent Laplacian system ``K h* = sum_T A_T G_T^T (R90 grad h_T)``
(Polthier's discrete conjugate in its least-squares form).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import NDArray


def triangle_areas(vertices: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.float64]:
    """Signed areas of the triangles, shape (T,); positive for counter-clockwise ones."""
    p0, p1, p2 = (vertices[triangles[:, k]] for k in range(3))
    e1, e2 = p1 - p0, p2 - p0
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def hat_gradients(vertices: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.float64]:
    """Gradients of the three hat functions on every triangle.

    Parameters
    ----------
    vertices : ndarray, shape (V, 2)
    triangles : ndarray of int, shape (T, 3), counter-clockwise

    Returns
    -------
    ndarray, shape (T, 3, 2)
        ``[t, i]`` is the gradient of the hat function of vertex ``triangles[t, i]`` on triangle
        t, in 1 / (units of the vertices).
    """
    areas2 = 2.0 * triangle_areas(vertices, triangles)
    points = vertices[triangles]  # (T, 3, 2)
    opposite = np.roll(points, -2, axis=1) - np.roll(points, -1, axis=1)  # p[i+2] - p[i+1]
    rotated = np.stack([-opposite[..., 1], opposite[..., 0]], axis=-1)
    return rotated / areas2[:, None, None]


def gradients(
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    corner_values: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Per-triangle gradient of a P1 function given by its values at the triangles' corners.

    Corner values (rather than vertex values) let a multivalued function, such as an angle
    with a 2 pi period, be differentiated on each triangle with its own branch.

    Parameters
    ----------
    vertices : ndarray, shape (V, 2)
    triangles : ndarray of int, shape (T, 3)
    corner_values : ndarray, shape (T, 3)

    Returns
    -------
    ndarray, shape (T, 2)
    """
    return np.einsum("tik,ti->tk", hat_gradients(vertices, triangles), corner_values)


def least_squares_potential(
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    stiffness: scipy.sparse.spmatrix,
    field: NDArray[np.float64],
    corner_offsets: NDArray[np.float64] | None = None,
    anchor: int = 0,
) -> NDArray[np.float64]:
    """The P1 function whose gradient best matches a per-triangle vector field.

    Minimises ``sum_T A_T |grad(phi + offsets)_T - field_T|^2`` over vertex values phi, with
    ``phi[anchor] = 0``. ``corner_offsets`` adds a known multivalued part per triangle corner
    (e.g. an angle's branch), so phi is its single-valued remainder.

    Parameters
    ----------
    vertices : ndarray, shape (V, 2)
    triangles : ndarray of int, shape (T, 3), counter-clockwise
    stiffness : sparse matrix, shape (V, V)
        The cotangent stiffness matrix of the mesh (``sum_T A_T G_T^T G_T``).
    field : ndarray, shape (T, 2)
    corner_offsets : ndarray, shape (T, 3), optional
    anchor : int
        Vertex whose value is fixed to 0 (the potential is defined up to a constant).

    Returns
    -------
    ndarray, shape (V,)
    """
    hats = hat_gradients(vertices, triangles)
    areas = triangle_areas(vertices, triangles)
    target = field
    if corner_offsets is not None:
        target = field - np.einsum("tik,ti->tk", hats, corner_offsets)
    # rhs_v = sum over triangles containing v of A_T * grad(hat_v) . target_T
    contributions = areas[:, None] * np.einsum("tik,tk->ti", hats, target)
    rhs = np.bincount(triangles.ravel(), weights=contributions.ravel(), minlength=len(vertices))
    keep = np.ones(len(vertices), dtype=bool)
    keep[anchor] = False
    matrix = scipy.sparse.csc_matrix(stiffness)[keep][:, keep]
    solution = np.zeros(len(vertices))
    solution[keep] = scipy.sparse.linalg.spsolve(matrix.tocsc(), rhs[keep])
    return solution


def rotate90(field: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate vectors by +90 degrees: (x, y) -> (-y, x); shape (..., 2)."""
    return np.stack([-field[..., 1], field[..., 0]], axis=-1)
