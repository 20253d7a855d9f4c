"""Aperture geometry from a validity mask: topology and boundary polygons.

An interferogram or a Shack-Hartmann frame comes with a 2-D mask of the pixels that carry
data. :class:`Aperture` turns that mask into what the fitters and the domain mappings need:
how many pieces the aperture has and how many holes (its topology), the boundary polygons in
physical coordinates, and the minimum enclosing circle of the valid pixels.

Conventions (project-wide): pixel centres sit at integer (row, col); physical coordinates are
``x = col`` and ``y = -row`` (row 0 is the top of the image, y points up); angles are measured
from +x, counter-clockwise.

Boundaries come from OpenCV's border following (Suzuki & Abe) with the two-level
``RETR_CCOMP`` hierarchy. The foreground (valid pixels) is 8-connected and holes are
4-connected, which is OpenCV's convention; components are counted with the same rule.
OpenCV traces the centres of the boundary pixels, half a pixel inside the edge of the pixel
region, so every vertex is pushed about half a pixel outward (outer polygons away from the
aperture, hole polygons into the hole; details in the Notes of :class:`Aperture`): an
axis-aligned k x k block of pixels then gives the k x k square exactly and the polygon area
is close to the pixel count.

References
----------
.. [1] S. Suzuki and K. Abe, "Topological structural analysis of digitized binary images by
   border following", Computer Vision, Graphics, and Image Processing 30(1), 32-46 (1985).
.. [2] OpenCV documentation, ``cv2.findContours`` and the contour hierarchy
   (``RETR_CCOMP``), ``cv2.connectedComponents``, ``cv2.minEnclosingCircle``.
"""

from __future__ import annotations

import enum
import math
import numbers
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Aperture", "EmptyAperture", "Topology", "UnsupportedAperture"]

_HALF = 0.5  # distance from a pixel centre to the edge of its pixel square, in pixels
_REVERSAL_COS = -1.0 + 1e-9  # cosine of the turn below which the contour doubles back
_CIRCLE_REL_MARGIN = 1e-9  # relative enlargement of the enclosing circle
_CIRCLE_ABS_MARGIN = 1e-12  # absolute enlargement of the enclosing circle, in pixels


class Topology(enum.Enum):
    """Connectivity class of an aperture.

    ``SIMPLY_CONNECTED`` is one component without hole (a disk), ``DOUBLY_CONNECTED`` one
    component with one hole (an annulus) and ``UNSUPPORTED`` anything else (several
    components, several holes).
    """

    SIMPLY_CONNECTED = "simply-connected"
    DOUBLY_CONNECTED = "doubly-connected"
    UNSUPPORTED = "unsupported"


class UnsupportedAperture(ValueError):
    """The aperture is neither simply nor doubly connected but the caller needs one that is.

    The message names what was found, e.g. ``"aperture has 2 components and 3 holes;
    expected one component with at most one hole"``.
    """


class EmptyAperture(ValueError):
    """The mask has no valid (non-zero) pixel."""


@dataclass(frozen=True, eq=False)
class Aperture:
    """Topology and boundary polygons of the valid region of a 2-D mask.

    Build one with :meth:`from_mask`; the constructor takes the fields as they are and does
    not check them.

    Attributes
    ----------
    mask : NDArray[np.bool_], shape (rows, cols)
        Read-only copy of the validity mask (True = valid pixel).
    outers : tuple of NDArray[np.float64], each shape (K, 2)
        One closed polygon per connected component (8-connectivity), vertices in physical
        coordinates (x, y) = (col, -row) in pixels, counter-clockwise (positive signed area),
        first vertex not repeated at the end. Sorted by decreasing pixel count of the
        component. Read-only.
    holes : tuple of NDArray[np.float64], each shape (K, 2)
        One closed polygon per hole (4-connected background region not connected to the image
        border) whose pixel count is at least ``min_hole_area_px``, in the same coordinates,
        clockwise (negative signed area). Sorted by decreasing pixel count. Read-only.
    topology : Topology
        ``SIMPLY_CONNECTED`` (1 component, 0 holes), ``DOUBLY_CONNECTED`` (1 component,
        1 hole) or ``UNSUPPORTED``; holes below the threshold do not count.
    components : int
        Number of 8-connected components of valid pixels.
    ignored_holes : int
        Number of holes smaller than ``min_hole_area_px`` pixels, left out of ``holes``.
    min_hole_area_px : float
        Pixel count from which a hole is kept, in pixels.

    Notes
    -----
    Each edge of the traced chain of boundary pixel centres is moved outward by 0.5 px when
    axis-aligned and by 0.5/sqrt(2) px when diagonal (the mean line of the staircase), each
    vertex goes to the intersection of its two offset edges, bounded to the closed pixel
    square of its boundary pixel, and chain ends (one-pixel-wide lines, single pixels) get a
    square cap. Consequences:

    * axis-aligned rectangles of pixels give their pixel region exactly, and the polygon
      area of other shapes is within a fraction of a pixel per boundary corner of the pixel
      count (Pick's theorem); a concave corner of the pixel region, which the 8-connected
      border cuts diagonally, is cut by a triangle of 1/8 px^2 (a rectangular hole of
      ``n`` pixels has area ``n - 0.5``);
    * every pixel centre inside an odd number of the polygons (outers and counted holes) is
      a valid pixel or a pixel of an ignored hole, and vice versa;
    * the polygons are simple and do not meet each other. This was checked for every 4 x 4
      mask and for random masks (pinches where parts meet only at a pixel corner, spurs,
      thin walls), but is not proven for every mask: a pathological mask might still give a
      self-touching polygon.

    Islands inside an ignored small hole still count as components.
    """

    mask: NDArray[np.bool_]
    outers: tuple[NDArray[np.float64], ...]
    holes: tuple[NDArray[np.float64], ...]
    topology: Topology
    components: int
    ignored_holes: int
    min_hole_area_px: float

    @classmethod
    def from_mask(cls, mask: ArrayLike, *, min_hole_area_px: float = 4.0) -> Aperture:
        """Analyse a validity mask.

        Parameters
        ----------
        mask : array_like, shape (rows, cols)
            Boolean or real numeric array; non-zero entries are valid pixels. It is copied.
        min_hole_area_px : float, optional
            Holes with fewer background pixels than this (in pixels, default 4) are counted
            in ``ignored_holes`` and left out of ``holes`` and of the topology. Must be finite
            and >= 0.

        Returns
        -------
        Aperture
            Topology, boundary polygons and a read-only copy of the mask. Masks that are
            neither simply nor doubly connected are accepted (``Topology.UNSUPPORTED``).

        Raises
        ------
        ValueError
            If ``mask`` is not a 2-D array of booleans or finite real numbers with at least
            one row and one column, or ``min_hole_area_px`` is not a finite number >= 0.
        EmptyAperture
            If ``mask`` has no valid pixel.
        """
        valid = _validated_mask(mask)
        threshold = _validated_min_hole_area(min_hole_area_px)
        if not valid.any():
            raise EmptyAperture(f"mask of shape {valid.shape} has no valid (non-zero) pixel")

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
        holes = len(hole_items)
        if components == 1 and holes == 0:
            topology = Topology.SIMPLY_CONNECTED
        elif components == 1 and holes == 1:
            topology = Topology.DOUBLY_CONNECTED
        else:
            topology = Topology.UNSUPPORTED
        valid.flags.writeable = False
        return cls(
            mask=valid,
            outers=tuple(poly for _, poly in outer_items),
            holes=tuple(poly for _, poly in hole_items),
            topology=topology,
            components=components,
            ignored_holes=ignored,
            min_hole_area_px=threshold,
        )

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the mask."""
        rows, cols = self.mask.shape
        return int(rows), int(cols)

    @property
    def valid_count(self) -> int:
        """Number of valid pixels."""
        return int(np.count_nonzero(self.mask))

    @property
    def outer(self) -> NDArray[np.float64]:
        """The outer polygon of a one-component aperture.

        Returns
        -------
        NDArray[np.float64], shape (K, 2)
            Counter-clockwise polygon in physical (x, y) pixel coordinates.

        Raises
        ------
        UnsupportedAperture
            If the aperture does not have exactly one component.
        """
        if self.components != 1:
            raise UnsupportedAperture(f"{self._counts()}; expected exactly one component")
        return self.outers[0]

    @property
    def hole(self) -> NDArray[np.float64] | None:
        """The single hole polygon, or None when there is no (counted) hole.

        Returns
        -------
        NDArray[np.float64], shape (K, 2), or None
            Clockwise polygon in physical (x, y) pixel coordinates.

        Raises
        ------
        UnsupportedAperture
            If the aperture has several holes of at least ``min_hole_area_px`` pixels.
        """
        if len(self.holes) > 1:
            raise UnsupportedAperture(f"{self._counts()}; expected at most one hole")
        return self.holes[0] if self.holes else None

    def require_supported(self) -> None:
        """Check that the aperture is simply or doubly connected.

        Raises
        ------
        UnsupportedAperture
            If the topology is ``UNSUPPORTED``; the message names the components and holes
            found.
        """
        if self.topology is Topology.UNSUPPORTED:
            raise UnsupportedAperture(
                f"{self._counts()}; expected one component with at most one hole"
            )

    def eroded(self, radius_px: int) -> Aperture:
        """The aperture shrunk by a disk of ``radius_px`` pixels (an elliptical structuring element).

        Used where a detection spreads the edge outward by a known amount, e.g. the local-contrast
        box of a carrier frame, which reaches half a box beyond the fringes.

        Parameters
        ----------
        radius_px : int
            Radius of the disk, pixels; 0 returns the aperture unchanged.

        Returns
        -------
        Aperture
            A new aperture from the eroded mask, with the same ``min_hole_area_px``.
        """
        if radius_px <= 0:
            return self
        size = 2 * int(radius_px) + 1
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        mask = cv2.erode(self.mask.astype(np.uint8), kernel).astype(bool)
        return Aperture.from_mask(mask, min_hole_area_px=self.min_hole_area_px)

    def enclosing_circle(self) -> tuple[float, float, float]:
        """Minimum enclosing circle of the valid pixel centres.

        The centre comes from ``cv2.minEnclosingCircle`` on the outer-contour pixel centres
        (the valid centre farthest from any point lies on an outer contour). The radius is the
        float64 distance from that centre to the farthest of those points, enlarged by a
        relative 1e-9 plus 1e-12 px, so every valid pixel centre lies at a distance <= r even
        though OpenCV works in float32.

        Returns
        -------
        tuple of float
            (cx, cy, r) in PIXEL coordinates: ``cx`` is a column, ``cy`` a row coordinate and
            ``r`` the radius, all in pixels. A single valid pixel gives r ~ 1e-12.
        """
        padded = cv2.copyMakeBorder(
            self.mask.astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0
        )
        contours, _ = cv2.findContours(
            padded, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE, offset=(-1, -1)
        )
        points = np.concatenate([c.reshape(-1, 2) for c in contours]).astype(np.float32)
        (cx, cy), _ = cv2.minEnclosingCircle(points)
        cx, cy = float(cx), float(cy)
        points64 = points.astype(np.float64)
        farthest = float(np.max(np.hypot(points64[:, 0] - cx, points64[:, 1] - cy)))
        r = farthest * (1.0 + _CIRCLE_REL_MARGIN) + _CIRCLE_ABS_MARGIN
        return cx, cy, r

    def describe(self) -> str:
        """One-line human description.

        Returns
        -------
        str
            E.g. ``"doubly connected: 1 component, 1 hole, 41234 valid pixels"``, followed by
            the number of ignored small holes when there are some.
        """
        text = (
            f"{self.topology.value.replace('-', ' ')}: "
            f"{_plural(self.components, 'component')}, {_plural(len(self.holes), 'hole')}, "
            f"{_plural(self.valid_count, 'valid pixel')}"
        )
        if self.ignored_holes:
            text += (
                f" ({_plural(self.ignored_holes, 'hole')} smaller than "
                f"{self.min_hole_area_px:g} px ignored)"
            )
        return text

    def _counts(self) -> str:
        """'aperture has N components and M holes' plus the ignored holes, for messages."""
        text = (
            f"aperture has {_plural(self.components, 'component')} and "
            f"{_plural(len(self.holes), 'hole')}"
        )
        if self.ignored_holes:
            text += (
                f" (plus {_plural(self.ignored_holes, 'hole')} smaller than "
                f"min_hole_area_px={self.min_hole_area_px:g} ignored)"
            )
        return text


def _plural(count: int, noun: str) -> str:
    """``'1 hole'``, ``'2 holes'``."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def _validated_mask(mask: ArrayLike) -> NDArray[np.bool_]:
    """Check ``mask`` and return a new boolean array (True = non-zero)."""
    try:
        arr = np.asarray(mask)
    except (ValueError, TypeError) as exc:
        raise ValueError(
            f"mask must be a 2-D array of booleans or real numbers; could not convert it ({exc})"
        ) from exc
    expected = "expected a 2-D array of booleans or finite real numbers with rows, cols >= 1"
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(f"mask has shape {arr.shape} (dtype {arr.dtype}); {expected}")
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"mask has dtype {arr.dtype} (shape {arr.shape}); {expected}")
    if arr.dtype.kind == "f":
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        if bad:
            raise ValueError(
                f"mask (shape {arr.shape}, dtype {arr.dtype}) has {bad} NaN or infinite "
                f"entries; {expected}"
            )
    return np.array(arr != 0, dtype=np.bool_)


def _validated_min_hole_area(value: float) -> float:
    """Check ``min_hole_area_px`` and return it as a float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(
            f"min_hole_area_px is {value!r} of type {type(value).__name__}; "
            "expected a finite real number >= 0 (pixels)"
        )
    threshold = float(value)
    if not math.isfinite(threshold) or threshold < 0.0:
        raise ValueError(
            f"min_hole_area_px is {threshold!r}; expected a finite real number >= 0 (pixels)"
        )
    return threshold


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
