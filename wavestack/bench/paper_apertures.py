"""The apertures of the seed paper's benchmark, as pixel masks.

Yang et al., section 3 and Figure 2: Type I, a non-convex butterfly r(t) = 1 + 0.25 cos 2t -
0.38 cos 4t; Type II, a 3.5:1 rounded rectangle (an off-axis TMA mirror); Type III, a highly
eccentric annulus, here with a circular and with a triangular hole. The paper gives the
butterfly's formula and the rectangle's aspect ratio only; sizes, the corner radius and the
holes' placement are ours (stated below), all on a 512 x 512 grid as in issue "CSF-QCM".
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

SIZE = 512
_CENTRE = (SIZE - 1) / 2
_EXTENT = 230.0  # largest radius of every shape, pixels


def _polar(shape: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    rows, cols = np.indices(shape, dtype=np.float64)
    x, y = cols - (shape[1] - 1) / 2, (shape[0] - 1) / 2 - rows
    return x, y


def butterfly_mask(size: int = SIZE) -> NDArray[np.bool_]:
    """Type I: r(t) = 1 + 0.25 cos 2t - 0.38 cos 4t, scaled so max r = 230 px (at 512 px)."""
    x, y = _polar((size, size))
    t = np.arctan2(y, x)
    r = 1 + 0.25 * np.cos(2 * t) - 0.38 * np.cos(4 * t)
    peak = max(1 + 0.25 * np.cos(2 * a) - 0.38 * np.cos(4 * a) for a in np.linspace(0, np.pi, 3601))
    return np.hypot(x, y) <= r * (_EXTENT * size / SIZE) / peak


def rounded_rectangle_mask(
    shape: tuple[int, int], half_length: float, half_width: float, corner: float
) -> NDArray[np.bool_]:
    """Mask of a centred rounded rectangle, long axis along x (sizes in pixels)."""
    x, y = _polar(shape)
    dx = np.abs(x) - (half_length - corner)
    dy = np.abs(y) - (half_width - corner)
    return np.hypot(np.maximum(dx, 0), np.maximum(dy, 0)) <= corner


def rectangle_mask(size: int = SIZE) -> NDArray[np.bool_]:
    """Type II: a 3.5:1 rounded rectangle, 460 x 131 px at 512 px, corner radius 20 px."""
    k = size / SIZE
    return rounded_rectangle_mask((size, size), _EXTENT * k, _EXTENT / 3.5 * k, 20.0 * k)


def annulus_circular_hole_mask(size: int = SIZE) -> NDArray[np.bool_]:
    """Type III: outer radius 230 px, circular hole of radius 70 px centred 120 px off axis.

    The gap is 40 px on the narrow side and 280 px on the wide one.
    """
    k = size / SIZE
    x, y = _polar((size, size))
    return (np.hypot(x, y) <= _EXTENT * k) & (np.hypot(x - 120 * k, y) > 70 * k)


def annulus_triangular_hole_mask(size: int = SIZE) -> NDArray[np.bool_]:
    """Type III variant: outer radius 230 px, an equilateral triangular hole off axis.

    The triangle has circumradius 80 px, its centre 90 px right and 30 px up of the centre, one
    vertex pointing to +x.
    """
    k = size / SIZE
    x, y = _polar((size, size))
    u, v = (x - 90 * k) / (80 * k), (y - 30 * k) / (80 * k)
    inside_triangle = np.ones_like(u, dtype=bool)
    for angle in (np.pi, np.pi / 3, -np.pi / 3):  # inward normals of the three sides
        inside_triangle &= u * np.cos(angle) + v * np.sin(angle) >= -0.5
    return (np.hypot(x, y) <= _EXTENT * k) & ~inside_triangle


PAPER_APERTURES: dict[str, Callable[[int], NDArray[np.bool_]]] = {
    "butterfly": butterfly_mask,
    "rounded-rectangle": rectangle_mask,
    "annulus-circular-hole": annulus_circular_hole_mask,
    "annulus-triangular-hole": annulus_triangular_hole_mask,
}
