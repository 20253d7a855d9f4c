"""Boundary polygons of a validity mask: OpenCV contours pushed half a pixel out, holes matched to
their background components.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

_HALF = 0.5  # distance from a pixel centre to the edge of its pixel square, in pixels
_REVERSAL_COS = -1.0 + 1e-9  # cosine of the turn below which the contour doubles back


def _hole_label(chain: NDArray[np.int64], bg_labels: NDArray[np.int32]) -> int:
    """Label of the background component enclosed by a hole contour.

    Parameters
    ----------
    chain : NDArray[np.int64], shape (K, 2)
        Hole contour from OpenCV, (col, row) pixel centres of foreground pixels.
    bg_labels : NDArray[np.int32], shape (rows + 2, cols + 2)
        4-connected labels of the background of the mask padded by one background pixel
        (0 on foreground pixels; the label at (0, 0) is the background reaching the border).

    Returns
    -------
    int
        The label of the hole: the background component 4-adjacent to the contour pixels and
        inside the contour. When several are adjacent (thin walls between holes, or between a
        hole and the outside), the one whose adjacent pixel lies inside the contour polygon.

    Raises
    ------
    RuntimeError
        If no such component exists (would be a bug; OpenCV hole borders always enclose one).
    """
    rows = chain[:, 1] + 1
    cols = chain[:, 0] + 1
    outside = int(bg_labels[0, 0])
    found: dict[int, tuple[int, int]] = {}
    for d_row, d_col in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        labels = bg_labels[rows + d_row, cols + d_col]
        for index in np.flatnonzero((labels != 0) & (labels != outside)):
            pixel = (int(rows[index] + d_row), int(cols[index] + d_col))
            found.setdefault(int(labels[index]), pixel)
    if len(found) == 1:
        return next(iter(found))
    contour = chain.reshape(-1, 1, 2).astype(np.int32)
    for label, (row, col) in found.items():
        if cv2.pointPolygonTest(contour, (float(col - 1), float(row - 1)), False) > 0:
            return label
    raise RuntimeError("internal error: no background component inside a hole contour")


def _offset_chain(chain: NDArray[np.int64]) -> NDArray[np.float64]:
    """Push an OpenCV boundary chain half a pixel outward from the valid region.

    Parameters
    ----------
    chain : NDArray[np.int64], shape (K, 2)
        Closed 8-connected chain of boundary pixel centres, (col, row), in OpenCV's traversal
        order: outer borders counter-clockwise and hole borders clockwise in physical
        coordinates, so the valid region is on the left of the direction of travel.

    Returns
    -------
    NDArray[np.float64], shape (M, 2)
        Read-only polygon in physical (x, y) coordinates, same orientation. Each edge is
        offset to the right of the direction of travel by 0.5 px (axis-aligned step) or
        0.5/sqrt(2) px (diagonal step) and each vertex moves to the intersection of its two
        offset edges (exact pixel edges for axis-aligned runs and right-angle corners),
        bounded to the pixel square of its boundary pixel at sharp turns. Where the chain
        doubles back (the end of a one-pixel-wide line) the vertex becomes a square cap: the
        two points where the offset edges meet the pixel square, plus the forward corner of
        the square for a diagonal run. A one-point chain (a single pixel) gives its unit
        square.
    """
    points = np.column_stack((chain[:, 0], -chain[:, 1])).astype(np.float64)
    if len(points) == 1:
        square = np.array([[-_HALF, -_HALF], [_HALF, -_HALF], [_HALF, _HALF], [-_HALF, _HALF]])
        polygon = points[0] + square
        polygon.flags.writeable = False
        return polygon

    step_out = np.roll(points, -1, axis=0) - points
    d_out = step_out / np.hypot(step_out[:, 0], step_out[:, 1])[:, None]
    d_in = np.roll(d_out, 1, axis=0)
    n_out = np.column_stack((d_out[:, 1], -d_out[:, 0]))  # right-hand normals
    n_in = np.roll(n_out, 1, axis=0)
    # Offset of each edge: 0.5 px for axis-aligned steps, 0.5 / sqrt(2) px for diagonal ones,
    # i.e. the line through the midpoints of the pixel-square sides that the staircase of a
    # diagonal run crosses. Each boundary step then adds 1/2 px^2, as in Pick's theorem.
    o_out = _HALF * np.max(np.abs(d_out), axis=1)
    o_in = np.roll(o_out, 1)
    cos_turn = np.einsum("ij,ij->i", d_in, d_out)
    det = n_in[:, 0] * n_out[:, 1] - n_in[:, 1] * n_out[:, 0]
    turning = np.abs(det) > 1e-9
    safe_det = np.where(turning, det, 1.0)
    # Intersection of the two offset lines (w . n_in = o_in, w . n_out = o_out).
    miter = np.column_stack(
        (
            (o_in * n_out[:, 1] - o_out * n_in[:, 1]) / safe_det,
            (n_in[:, 0] * o_out - n_out[:, 0] * o_in) / safe_det,
        )
    )
    miter = np.where(turning[:, None], miter, o_out[:, None] * n_out)
    reversal = cos_turn < _REVERSAL_COS
    diagonal = np.min(np.abs(d_in), axis=1) > 1e-9

    # Vertex i gives 1 point, or a square cap where the chain doubles back: the two points
    # where the offset lines meet the pixel square, plus its forward corner for diagonal runs.
    counts = np.where(reversal, np.where(diagonal, 3, 2), 1)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    shift = np.empty((int(counts.sum()), 2))
    shift[starts] = np.where(reversal[:, None], o_in[:, None] * (d_in + n_in), miter)
    corner = reversal & diagonal
    shift[starts[corner] + 1] = _HALF * np.sign(d_in[corner])
    last = starts[reversal] + counts[reversal] - 1
    shift[last] = o_in[reversal, None] * (d_in[reversal] - n_in[reversal])
    norm = np.max(np.abs(shift), axis=1)
    shift *= np.minimum(1.0, _HALF / norm)[:, None]
    polygon = np.repeat(points, counts, axis=0) + shift

    keep = np.any(polygon != np.roll(polygon, -1, axis=0), axis=1)
    polygon = np.ascontiguousarray(polygon[keep])
    polygon.flags.writeable = False
    return polygon


def _boundary_polygons(
    valid: NDArray[np.bool_], threshold: float
) -> tuple[tuple[NDArray[np.float64], ...], tuple[NDArray[np.float64], ...], int, int]:
    """Outer and hole boundary polygons of a non-empty mask, largest first.

    Parameters
    ----------
    valid : NDArray[np.bool_], shape (rows, cols)
        The valid pixels; at least one is True.
    threshold : float
        Holes with fewer background pixels than this are ignored (counted, not returned).

    Returns
    -------
    outers, holes : tuple of NDArray[np.float64], each shape (M, 2)
        Read-only polygons in physical (x, y) pixel coordinates (see :func:`_offset_chain`),
        sorted by the pixel count of their component, largest first.
    components : int
        8-connected components of the valid pixels.
    ignored : int
        Holes below ``threshold``.
    """
    padded = cv2.copyMakeBorder(
        valid.astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0
    )
    contours, hierarchy = cv2.findContours(
        padded, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE, offset=(-1, -1)
    )
    parents = hierarchy.reshape(-1, 4)[:, 3]
    chains = [np.asarray(c, dtype=np.int64).reshape(-1, 2) for c in contours]

    n_fg, fg_labels, fg_stats, _ = cv2.connectedComponentsWithStats(
        padded, connectivity=8, ltype=cv2.CV_32S
    )
    _, bg_labels, bg_stats, _ = cv2.connectedComponentsWithStats(
        1 - padded, connectivity=4, ltype=cv2.CV_32S
    )
    fg_sizes = fg_stats[:, cv2.CC_STAT_AREA]
    bg_sizes = bg_stats[:, cv2.CC_STAT_AREA]

    outer_items: list[tuple[int, NDArray[np.float64]]] = []
    hole_items: list[tuple[int, NDArray[np.float64]]] = []
    ignored = 0
    for chain, parent in zip(chains, parents, strict=True):
        if parent < 0:
            col, row = chain[0]
            size = int(fg_sizes[fg_labels[row + 1, col + 1]])
            outer_items.append((size, _offset_chain(chain)))
        else:
            size = int(bg_sizes[_hole_label(chain, bg_labels)])
            if size >= threshold:
                hole_items.append((size, _offset_chain(chain)))
            else:
                ignored += 1

    components = n_fg - 1
    if components != len(outer_items):
        raise RuntimeError(
            f"internal error: {components} 8-connected components but "
            f"{len(outer_items)} outer contours"
        )
    outer_items.sort(key=lambda item: -item[0])
    hole_items.sort(key=lambda item: -item[0])
    return (
        tuple(poly for _, poly in outer_items),
        tuple(poly for _, poly in hole_items),
        components,
        ignored,
    )
