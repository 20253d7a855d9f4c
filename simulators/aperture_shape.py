"""The clear aperture of the simulated test optic: its shape in pixels and its rasterisation.

An :class:`ApertureShape` (circle, annulus, ellipse, rectangle or polygon) is what
:class:`~wavestack.simulators.optic.TestOptic` renders fringes inside. Geometry is given as
``(col, row)`` pairs in pixels (rows grow downward); pixel ``(row, col)`` has its centre at the
integer point ``(col, row)``. Rotations are counter-clockwise as the image is displayed, i.e. from
``+col`` towards ``-row``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.simulators._checks import finite_number, number_pair

ApertureKind = Literal["circle", "annulus", "ellipse", "rectangle", "polygon"]


@dataclass(frozen=True)
class ApertureShape:
    """The clear aperture of the test optic on the camera, in pixels.

    Attributes
    ----------
    kind : {"circle", "annulus", "ellipse", "rectangle", "polygon"}
        Which of the fields below describe the shape.
    centre_px : (float, float)
        ``(col, row)`` of the centre (circle, annulus outer circle, ellipse, rectangle).
    radius_px : float
        Radius of the circle, or of the annulus's outer circle, ``> 0``.
    inner_radius_px : float
        Annulus: radius of the central obscuration, ``0 < inner < radius``.
    obscuration_centre_px : (float, float) or None
        Annulus: ``(col, row)`` of the obscuration's centre, which may be off-centre but must
        lie with its whole disk inside the outer circle; None means ``centre_px``.
    semi_axes_px : (float, float)
        Ellipse: semi-axes ``(a, b)``; rectangle: half-widths ``(a, b)``; ``a`` along the
        rotated first axis, both ``> 0``.
    rotation_deg : float
        Ellipse and rectangle: angle of the first axis from ``+col`` towards ``-row`` (counter-
        clockwise as displayed), degrees.
    vertices_px : tuple of (float, float)
        Polygon: ``(col, row)`` of at least 3 vertices in order, closed implicitly. It may be
        non-convex; it should not cross itself (the even-odd rule decides inside then).

    Raises
    ------
    ValueError
        If a field the kind needs is missing or out of range; the message names it.
    """

    kind: ApertureKind = "circle"
    centre_px: tuple[float, float] = (512.0, 512.0)
    radius_px: float = 400.0
    inner_radius_px: float = 0.0
    obscuration_centre_px: tuple[float, float] | None = None
    semi_axes_px: tuple[float, float] = (400.0, 300.0)
    rotation_deg: float = 0.0
    vertices_px: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in ("circle", "annulus", "ellipse", "rectangle", "polygon"):
            raise ValueError(
                f"kind: expected circle, annulus, ellipse, rectangle or polygon, got {self.kind!r}"
            )
        centre = number_pair(self.centre_px, "centre_px")
        if self.kind in ("circle", "annulus") and finite_number(self.radius_px, "radius_px") <= 0:
            raise ValueError(f"radius_px: expected > 0 pixels, got {self.radius_px!r}")
        if self.kind == "annulus":
            inner = finite_number(self.inner_radius_px, "inner_radius_px")
            hole = centre if self.obscuration_centre_px is None else number_pair(
                self.obscuration_centre_px, "obscuration_centre_px"
            )
            if not 0 < inner < self.radius_px:
                raise ValueError(
                    f"inner_radius_px: expected 0 < inner < radius_px = {self.radius_px}, got {inner!r}"
                )
            if math.hypot(hole[0] - centre[0], hole[1] - centre[1]) + inner >= self.radius_px:
                raise ValueError(
                    f"obscuration_centre_px: the obscuration of radius {inner} at {hole} must lie "
                    f"inside the outer circle of radius {self.radius_px} at {centre}"
                )
        if self.kind in ("ellipse", "rectangle"):
            a, b = number_pair(self.semi_axes_px, "semi_axes_px")
            if a <= 0 or b <= 0:
                raise ValueError(f"semi_axes_px: expected two numbers > 0, got {self.semi_axes_px!r}")
            finite_number(self.rotation_deg, "rotation_deg")
        if self.kind == "polygon":
            if len(self.vertices_px) < 3:
                raise ValueError(f"vertices_px: expected at least 3 (col, row) vertices, got {self.vertices_px!r}")
            for index, vertex in enumerate(self.vertices_px):
                number_pair(vertex, f"vertices_px[{index}]")

    def bounds(self) -> tuple[float, float, float, float]:
        """``(col_min, col_max, row_min, row_max)`` of a box holding the shape, pixels."""
        cx, cy = self.centre_px
        if self.kind in ("circle", "annulus"):
            r = self.radius_px
            return cx - r, cx + r, cy - r, cy + r
        if self.kind == "polygon":
            points = np.asarray(self.vertices_px, dtype=np.float64)
            return (float(points[:, 0].min()), float(points[:, 0].max()),
                    float(points[:, 1].min()), float(points[:, 1].max()))
        r = math.hypot(*self.semi_axes_px)  # the rotated shape lies within its circumcircle
        return cx - r, cx + r, cy - r, cy + r

    def contains(self, cols: ArrayLike, rows: ArrayLike) -> NDArray[np.bool_]:
        """Which points lie inside the aperture (boundary included, except polygon ties).

        Parameters
        ----------
        cols, rows : array_like, same shape
            Point coordinates in pixels (column right, row down).

        Returns
        -------
        ndarray of bool, the shape of ``cols``
            Polygons use the even-odd crossing rule (half-open in rows), the other kinds the
            closed analytic inequalities.
        """
        x = np.asarray(cols, dtype=np.float64)
        y = np.asarray(rows, dtype=np.float64)
        cx, cy = self.centre_px
        if self.kind in ("circle", "annulus"):
            inside = (x - cx) ** 2 + (y - cy) ** 2 <= self.radius_px**2
            if self.kind == "annulus":
                hx, hy = self.obscuration_centre_px or self.centre_px
                inside &= (x - hx) ** 2 + (y - hy) ** 2 > self.inner_radius_px**2
            return inside
        if self.kind == "polygon":
            return _even_odd(np.asarray(self.vertices_px, dtype=np.float64), x, y)
        angle = math.radians(self.rotation_deg)
        dx, dy_up = x - cx, cy - y
        along = dx * math.cos(angle) + dy_up * math.sin(angle)
        across = -dx * math.sin(angle) + dy_up * math.cos(angle)
        a, b = self.semi_axes_px
        if self.kind == "ellipse":
            return (along / a) ** 2 + (across / b) ** 2 <= 1.0
        return (np.abs(along) <= a) & (np.abs(across) <= b)

    def mask(self, height: int, width: int) -> NDArray[np.bool_]:
        """Rasterise the aperture: a pixel is valid when its centre lies inside.

        Parameters
        ----------
        height, width : int
            Frame size, pixels.

        Returns
        -------
        ndarray of bool, shape (height, width)
        """
        out = np.zeros((height, width), dtype=bool)
        c0, c1, r0, r1 = self.bounds()
        cols = np.arange(max(0, math.floor(c0)), min(width, math.ceil(c1) + 1))
        rows = np.arange(max(0, math.floor(r0)), min(height, math.ceil(r1) + 1))
        if cols.size and rows.size:
            out[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1] = self.contains(cols[None, :], rows[:, None])
        return out


def _even_odd(vertices: NDArray[np.float64], x: NDArray, y: NDArray) -> NDArray[np.bool_]:
    """Crossing-number point-in-polygon test (W. R. Franklin's PNPOLY), vectorised over points."""
    x, y = np.broadcast_arrays(x, y)
    inside = np.zeros(x.shape, dtype=bool)
    for (x1, y1), (x2, y2) in zip(vertices, np.roll(vertices, -1, axis=0)):
        if y1 == y2:
            continue  # a horizontal edge never crosses a row half-openly
        crosses = (y1 > y) != (y2 > y)
        x_cross = x1 + (y - y1) * ((x2 - x1) / (y2 - y1))
        inside ^= crosses & (x < x_cross)
    return inside
