"""Small plane-geometry pieces of the aperture mesher: cross products, signed areas, corner angles,
unique edges, membership.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def _cross(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """z component of the cross product of the rows of two (N, 2) arrays."""
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def _polygon_area(polygon: NDArray[np.float64]) -> float:
    """Signed (shoelace) area of a closed polygon given without repeated end, in px^2."""
    x, y = polygon[:, 0], polygon[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _signed_areas(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Signed area of each triangle, shape (T,), positive when counter-clockwise."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * _cross(b - a, c - a)


def _corner_angles(
    vertices: NDArray[np.float64], triangles: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Interior angles in radians, shape (T, 3); column k is the angle at vertex k."""
    p = vertices[triangles]
    angles = np.empty(triangles.shape)
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        angles[:, k] = np.arctan2(np.abs(_cross(u, v)), np.sum(u * v, axis=1))
    return angles


def _unique_edges(triangles: NDArray[np.int64], n_vertices: int) -> NDArray[np.int64]:
    """Unique undirected edges (i < j), sorted lexicographically, shape (E, 2)."""
    pairs = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    low = np.minimum(pairs[:, 0], pairs[:, 1]).astype(np.int64)
    high = np.maximum(pairs[:, 0], pairs[:, 1]).astype(np.int64)
    keys = np.sort(low * n_vertices + high)
    keys = keys[np.concatenate(([True], keys[1:] != keys[:-1]))] if len(keys) else keys
    return np.column_stack((keys // n_vertices, keys % n_vertices))


def _member(values: NDArray[np.int64], pool: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Which ``values`` occur in the sorted array ``pool`` (binary search)."""
    if len(pool) == 0:
        return np.zeros(len(values), dtype=bool)
    position = np.minimum(np.searchsorted(pool, values), len(pool) - 1)
    return np.asarray(pool[position] == values)
