"""The boundary of an aperture mesh: polygons as arc-length curves, their sharp corners, and their
resampling at near-uniform spacing (steps 1 and 4 of :func:`~wavestack.pipeline.mapping.mesh.mesh_aperture`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .mesh_geometry import _cross, _polygon_area


_CORNER_TURN = math.radians(50.0)  # turn from which a polygon vertex is kept as a corner
_CORNER_WINDOW_PX = 3.0  # smallest arc-length window of the corner test, in pixels
_MIN_LOOP_VERTICES = 3


@dataclass(frozen=True, eq=False)
class _Curve:
    """A closed polygon parametrised by arc length.

    ``closed`` (K + 1, 2) repeats the first vertex at the end; ``cum`` (K + 1,) is the arc
    length at each of its vertices, in pixels.
    """

    closed: NDArray[np.float64]
    cum: NDArray[np.float64]

    @classmethod
    def from_polygon(cls, polygon: NDArray[np.float64]) -> _Curve:
        closed = np.vstack([polygon, polygon[:1]])
        steps = np.hypot(*np.diff(closed, axis=0).T)
        return cls(closed=closed, cum=np.concatenate(([0.0], np.cumsum(steps))))

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    @property
    def signed_area(self) -> float:
        return _polygon_area(self.closed[:-1])

    def at(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points at arc lengths ``s`` (taken modulo the length), on the polygon's edges."""
        t = np.mod(s, self.length)
        return np.column_stack(
            (np.interp(t, self.cum, self.closed[:, 0]), np.interp(t, self.cum, self.closed[:, 1]))
        )


def _corners(curve: _Curve, window: float) -> NDArray[np.float64]:
    """Arc lengths of the polygon vertices kept as corners, increasing.

    A vertex is a candidate when the chords from the point ``window`` before it and to the
    point ``window`` after it (along the polygon) turn by more than _CORNER_TURN; candidates
    are accepted greedily by decreasing turn, at least ``window`` from accepted corners.
    """
    length = curve.length
    if length < 4.0 * window:
        return np.empty(0)
    s = curve.cum[:-1]
    here = curve.closed[:-1]
    incoming = here - curve.at(s - window)
    outgoing = curve.at(s + window) - here
    turn = np.abs(np.arctan2(_cross(incoming, outgoing), np.sum(incoming * outgoing, axis=1)))
    candidates = np.flatnonzero(turn > _CORNER_TURN)
    candidates = candidates[np.argsort(-turn[candidates], kind="stable")]
    chosen: list[float] = []
    for index in candidates:
        gaps = np.abs(np.asarray(chosen) - s[index])
        if np.all(np.minimum(gaps, length - gaps) >= window):
            chosen.append(float(s[index]))
    return np.sort(np.asarray(chosen, dtype=np.float64))


def _resample(curve: _Curve, h: float) -> NDArray[np.float64]:
    """Arc lengths of the resampled loop: the corners, and uniform pieces between them.

    Returns an increasing array spanning less than one turn; values may exceed the length
    (they are used modulo the length).
    """
    length = curve.length
    breaks = _corners(curve, max(h, _CORNER_WINDOW_PX))
    if breaks.size == 0:
        count = max(_MIN_LOOP_VERTICES, round(length / h))
        return np.arange(count) * (length / count)
    pieces = np.diff(np.append(breaks, breaks[0] + length))
    counts = np.maximum(1, np.rint(pieces / h).astype(np.int64))
    if counts.sum() < _MIN_LOOP_VERTICES:
        counts[np.argmax(pieces)] += _MIN_LOOP_VERTICES - counts.sum()
    piece = np.repeat(np.arange(len(breaks)), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return breaks[piece] + pieces[piece] * k / counts[piece]


def _split(
    s: NDArray[np.float64], missing: NDArray[np.bool_], length: float
) -> NDArray[np.float64]:
    """Insert the arc-length midpoint of every missing chord (chord k joins k and k + 1)."""
    if not missing.any():
        return s
    following = np.append(s[1:], s[0] + length)
    midpoints = 0.5 * (s + following)[missing]
    return np.insert(s, np.flatnonzero(missing) + 1, midpoints)


def _chords(loops: list[NDArray[np.float64]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Start and end points of every boundary chord, each shape (C, 2)."""
    starts = np.vstack(loops)
    ends = np.vstack([np.roll(loop, -1, axis=0) for loop in loops])
    return starts, ends


def _loop_indices(sizes: list[int]) -> tuple[NDArray[np.int64], ...]:
    """Vertex indices of the loops, which come first and in order."""
    starts = np.cumsum([0, *sizes[:-1]])
    return tuple(
        np.arange(start, start + size, dtype=np.int64)
        for start, size in zip(starts, sizes, strict=True)
    )
