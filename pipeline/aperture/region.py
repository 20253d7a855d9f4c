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
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import real_at_least
from .contours import _boundary_polygons

__all__ = ["Aperture", "EmptyAperture", "Topology", "UnsupportedAperture"]

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

        Examples
        --------
        A disk of radius 30 px, then the same disk with a central hole:

        >>> import numpy as np
        >>> rows, cols = np.mgrid[:64, :64]
        >>> r2 = (rows - 31.5) ** 2 + (cols - 31.5) ** 2
        >>> aperture = Aperture.from_mask(r2 < 30**2)
        >>> aperture.topology.name, aperture.valid_count
        ('SIMPLY_CONNECTED', 2828)
        >>> Aperture.from_mask((r2 < 30**2) & (r2 > 10**2)).describe()
        'doubly connected: 1 component, 1 hole, 2512 valid pixels'
        """
        valid = _validated_mask(mask)
        threshold = _validated_min_hole_area(min_hole_area_px)
        if not valid.any():
            raise EmptyAperture(f"mask of shape {valid.shape} has no valid (non-zero) pixel")

        outers, holes, components, ignored = _boundary_polygons(valid, threshold)
        if components == 1 and len(holes) == 0:
            topology = Topology.SIMPLY_CONNECTED
        elif components == 1 and len(holes) == 1:
            topology = Topology.DOUBLY_CONNECTED
        else:
            topology = Topology.UNSUPPORTED
        valid.flags.writeable = False
        return cls(
            mask=valid,
            outers=outers,
            holes=holes,
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
    return real_at_least(value, "min_hole_area_px", 0.0, unit="pixels", voice="is")
