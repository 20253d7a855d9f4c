"""The three sub-steps of one curve-shortening iteration (semi-implicit CSF step, tangential
redistribution, renormalisation) and the circularity measure; the scheme is described in
:mod:`wavestack.pipeline.mapping.csf`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solveh_banded

FloatArray = NDArray[np.float64]


def _edges(z: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Edge vectors ``z_{i+1} - z_i`` (cyclic), shape (2, K), and their lengths, shape (K,)."""
    edge = np.empty_like(z)
    np.subtract(z[:, 1:], z[:, :-1], out=edge[:, :-1])
    np.subtract(z[:, :1], z[:, -1:], out=edge[:, -1:])
    return edge, np.sqrt(edge[0] * edge[0] + edge[1] * edge[1])


def _implicit_step(z: FloatArray, length: FloatArray, dt: float) -> FloatArray:
    """One step ``(M + dt S) z_new = M z`` of the P1 arc-length heat equation (Eq. 1).

    ``length`` holds the current edge lengths.  The cyclic tridiagonal SPD matrix ``A`` is
    written ``A = B + u u^T / gamma`` with ``gamma = -A_00`` and ``u = (gamma, 0, ..., 0,
    A_{K-1,0})``, so that ``B`` is plain tridiagonal and SPD (``B = A + u u^T / |gamma|``);
    Sherman-Morrison then gives ``A^{-1} r = y - w (v.y) / (1 + v.w)`` with ``B y = r``,
    ``B w = u`` and ``v = u / gamma``.
    """
    count = len(length)
    weight = dt / np.maximum(length, np.finfo(np.float64).tiny)  # dt * S edge weights
    mass = np.empty(count)
    np.add(length[1:], length[:-1], out=mass[1:])
    mass[0] = length[0] + length[-1]
    mass *= 0.5  # lumped mass (l_{i-1} + l_i) / 2 at vertex i
    banded = np.empty((2, count))
    banded[0, 0] = 0.0
    np.negative(weight[:-1], out=banded[0, 1:])
    diagonal = banded[1]
    np.add(mass, weight, out=diagonal)
    diagonal[1:] += weight[:-1]
    diagonal[0] += weight[-1]
    corner = -weight[-1]  # A[K-1, 0] = A[0, K-1]
    gamma = -diagonal[0]
    diagonal[0] -= gamma
    diagonal[-1] -= corner * corner / gamma
    rhs = np.zeros((count, 3))
    rhs[:, 0] = mass * z[0]
    rhs[:, 1] = mass * z[1]
    rhs[0, 2] = gamma
    rhs[-1, 2] = corner
    solution = solveh_banded(banded, rhs, check_finite=False)
    y = solution[:, :2].T
    w = solution[:, 2]
    v_dot_y = y[:, 0] + (corner / gamma) * y[:, -1]
    v_dot_w = w[0] + (corner / gamma) * w[-1]
    return y - np.outer(v_dot_y / (1.0 + v_dot_w), w)


def _redistribute(z: FloatArray, edge: FloatArray, length: FloatArray) -> FloatArray:
    """Resample the polygon at K points equally spaced in arc length, from vertex 0 on."""
    count = len(length)
    arc = np.empty(count + 1)
    arc[0] = 0.0
    np.cumsum(length, out=arc[1:])
    target = arc[-1] * (np.arange(count) / count)
    index = np.searchsorted(arc, target, side="right") - 1
    np.clip(index, 0, count - 1, out=index)
    fraction = (target - arc[index]) / np.maximum(length[index], np.finfo(np.float64).tiny)
    np.clip(fraction, 0.0, 1.0, out=fraction)
    return z[:, index] + fraction * edge[:, index]


def _renormalise(z: FloatArray, area0: float, centroid0: FloatArray) -> FloatArray:
    """Scale about the area centroid to the area ``area0``; move the centroid to ``centroid0``."""
    area, centroid = _area_centroid(z)
    ratio = area0 / area if area != 0.0 else math.nan
    if not (math.isfinite(ratio) and ratio > 0.0) or not np.all(np.isfinite(z)):
        raise FloatingPointError(
            "curve_shortening_flow broke down: the enclosed area changed sign or became non-finite"
        )
    return centroid0[:, None] + math.sqrt(ratio) * (z - centroid[:, None])


def _area_centroid(z: FloatArray) -> tuple[float, FloatArray]:
    """Signed area (positive counter-clockwise) and area centroid, shape (2,), of a polygon.

    Coordinates are taken relative to the vertex mean first, so that a polygon far from the
    origin does not lose digits in the shoelace sums.
    """
    origin = z.mean(axis=1)
    p = z - origin[:, None]
    q = np.empty_like(p)
    q[:, :-1] = p[:, 1:]
    q[:, -1] = p[:, 0]
    cross = p[0] * q[1] - q[0] * p[1]
    area = 0.5 * float(cross.sum())
    if area == 0.0:
        return 0.0, origin
    centroid = origin + ((p + q) @ cross) / (6.0 * area)
    return area, centroid


def _deficit(area: float, perimeter: float) -> float:
    """Isoperimetric deficit ``E_circ = 1 - 4 pi |A| / P^2`` (0 only for a circle)."""
    return 1.0 - 4.0 * math.pi * abs(area) / (perimeter * perimeter)
