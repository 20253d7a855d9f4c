"""Checks of a closed boundary polygon before it is flowed: shape, finiteness, orientation, and no
self-intersection.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .csf_step import _area_centroid, _edges

FloatArray = NDArray[np.float64]


_MIN_VERTICES = 8
_PAIR_CHUNK = 1 << 20  # candidate edge pairs tested at once by the self-intersection check


def _validate_points(points: ArrayLike) -> FloatArray:
    """Return ``points`` as a fresh float64 ``(K, 2)`` array or raise ValueError."""
    try:
        x = np.array(points, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(
            f"points: expected a real (K, 2) array, got {type(points).__name__}"
        ) from error
    if x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"points: expected shape (K, 2), got {x.shape}")
    if len(x) < _MIN_VERTICES:
        raise ValueError(f"points: expected K >= {_MIN_VERTICES} vertices, got {len(x)}")
    if not np.all(np.isfinite(x)):
        raise ValueError("points: expected finite coordinates, found NaN or inf")
    _, length = _edges(x.T)
    scale = float(np.max(np.abs(x - x.mean(axis=0))))
    if np.any(length <= 1e-12 * scale):
        first = int(np.argmax(length <= 1e-12 * scale))
        raise ValueError(
            f"points: expected distinct consecutive vertices (no repeated closing point), "
            f"vertices {first} and {(first + 1) % len(x)} coincide"
        )
    area, _ = _area_centroid(x.T)
    perimeter = float(length.sum())
    if abs(area) <= 1e-10 * perimeter * perimeter:
        raise ValueError(f"points: expected a polygon enclosing an area, got area {area:.3g}")
    crossing = _self_intersection(x)
    if crossing is not None:
        raise ValueError(
            f"points: expected a simple (non-self-intersecting) polygon, edges {crossing[0]} "
            f"and {crossing[1]} intersect"
        )
    return x


def _self_intersection(x: FloatArray) -> tuple[int, int] | None:
    """A pair of edges of the closed polygon that meet other than at a shared vertex, or None.

    Sweep along the longer side of the bounding box (say x): edges sorted by their left end,
    each tested against the edges whose x-range starts inside its own, then filtered by
    y-range and decided by orientation signs (touching and collinear overlap count as
    intersections).  Adjacent edges are checked
    separately for folding back onto each other.  Typical cost O(K sqrt K); worst case (all
    edges overlapping in x) O(K^2) in chunks of ``_PAIR_CHUNK`` pairs.
    """
    count = len(x)
    start = x
    end = np.roll(x, -1, axis=0)
    edge = end - start
    previous = np.roll(edge, 1, axis=0)
    fold = (previous[:, 0] * edge[:, 1] - previous[:, 1] * edge[:, 0] == 0.0) & (
        np.einsum("ij,ij->i", previous, edge) < 0.0
    )
    if np.any(fold):
        i = int(np.argmax(fold))
        return (i - 1) % count, i

    sweep = int(np.argmax(np.ptp(x, axis=0)))  # along the longer side of the bounding box
    other = 1 - sweep
    lo = np.minimum(start, end)
    hi = np.maximum(start, end)
    order = np.argsort(lo[:, sweep], kind="stable")
    sorted_lo = lo[order, sweep]
    reach = np.searchsorted(sorted_lo, hi[order, sweep], side="right")
    counts = np.maximum(reach - np.arange(1, count + 1), 0)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    first_row = 0
    while first_row < count:
        budget = offsets[first_row] + _PAIR_CHUNK
        last_row = int(np.searchsorted(offsets, budget, side="right")) - 1
        last_row = min(max(last_row, first_row + 1), count)
        rows = np.arange(first_row, last_row)
        n_pairs = counts[rows]
        rank_a = np.repeat(rows, n_pairs)
        row_start = np.repeat(offsets[rows] - offsets[first_row], n_pairs)
        local = np.arange(int(n_pairs.sum())) - row_start
        rank_b = rank_a + 1 + local
        a = order[rank_a]
        b = order[rank_b]
        gap = np.abs(a - b)
        keep = (gap != 1) & (gap != count - 1)
        keep &= (lo[a, other] <= hi[b, other]) & (lo[b, other] <= hi[a, other])
        a, b = a[keep], b[keep]
        hit = _segments_meet(start[a], end[a], start[b], end[b])
        if np.any(hit):
            k = int(np.argmax(hit))
            first, second = sorted((int(a[k]), int(b[k])))
            return first, second
        first_row = last_row
    return None


def _segments_meet(
    p1: FloatArray, p2: FloatArray, q1: FloatArray, q2: FloatArray
) -> NDArray[np.bool_]:
    """Whether closed segments ``p1p2`` and ``q1q2`` (with overlapping bounding boxes) meet."""

    def orient(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
        ab, ac = b - a, c - a
        return np.sign(ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])

    o1, o2 = orient(p1, p2, q1), orient(p1, p2, q2)
    o3, o4 = orient(q1, q2, p1), orient(q1, q2, p2)
    # Bounding boxes overlap (checked by the caller), so the collinear case (all zero) is a hit.
    return (o1 * o2 <= 0) & (o3 * o4 <= 0)
