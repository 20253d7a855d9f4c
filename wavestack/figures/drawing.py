"""What every wavestack figure draws the same way: maps in false colour, aperture outlines, coefficient bars.

matplotlib's Agg backend through the object API (a ``Figure`` given its own ``FigureCanvasAgg``):
nothing global is set, so figures can be made from any thread and never open a window. A map is
drawn on its pixel grid (x = column, y = row, row 0 at the top, as the camera sees it) unless the
caller gives it a physical extent; every map gets a colour bar whose label carries the unit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from numpy.typing import ArrayLike, NDArray

from wavestack.pipeline import mode_name

__all__ = [
    "BAR_COLOUR", "DPI", "MAGNITUDE_CMAP", "MAX_BARS", "SIGNED_CMAP", "aperture_outline", "coefficient_bars",
    "data_limits", "map_panel",
    "mesh_panel", "mode_label", "new_figure", "pixel_extent", "save_figure", "symmetric_limits",
]

#: Resolution of every figure, dots per inch: a figure of W x H inches is a PNG of W*DPI x H*DPI pixels.
DPI = 80
#: Colour map of signed quantities (wavefront, surface, residual, error): blue low, red high, white zero.
SIGNED_CMAP = "RdBu_r"
#: Colour map of magnitudes (|mu|, |G|, area scale): perceptually uniform.
MAGNITUDE_CMAP = "viridis"
#: Fill colour of coefficient bars and histograms.
BAR_COLOUR = "#1f77b4"
#: Bars drawn at most; a longer vector shows its first this many (the title says so).
MAX_BARS = 48


def new_figure(width_in: float, height_in: float) -> Figure:
    """An empty figure of ``width_in`` x ``height_in`` inches at :data:`DPI`, on its own Agg canvas.

    Example
    -------
    >>> figure = new_figure(4, 3)
    >>> tuple(figure.canvas.get_width_height())
    (320, 240)
    """
    figure = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure: Figure, path: str | Path) -> Path:
    """Write ``figure`` as a PNG of exactly its size in pixels (no tight cropping); returns the path.

    Saving at the figure's own dpi keeps the axes transforms valid afterwards: a pixel of the file
    is the display pixel the transforms name.
    """
    target = Path(path)
    figure.savefig(target, dpi=figure.dpi, format="png")
    return target


def symmetric_limits(*maps: ArrayLike) -> tuple[float, float]:
    """Colour limits ``(-b, b)`` with ``b`` the largest finite ``|value|`` over all maps (1 if none).

    A signed map is read against zero, so its scale is centred there; maps that share the limits
    can be compared colour for colour.

    Example
    -------
    >>> symmetric_limits([1.0, -3.0, np.nan], [2.0])
    (-3.0, 3.0)
    """
    bound = 0.0
    for values in maps:
        array = np.asarray(values, dtype=np.float64)
        finite = array[np.isfinite(array)]
        if finite.size:
            bound = max(bound, float(np.max(np.abs(finite))))
    bound = bound if math.isfinite(bound) and bound > 0 else 1.0
    return -bound, bound


def data_limits(data: ArrayLike) -> tuple[float, float]:
    """Colour limits spanning the finite values of ``data`` (``(0, 1)`` if there are none; widened if flat).

    For maps read on their own range rather than against zero (a dwell density, a height map).

    Example
    -------
    >>> data_limits([2.0, np.nan, 5.0])
    (2.0, 5.0)
    """
    array = np.asarray(data, dtype=np.float64)
    finite = array[np.isfinite(array)]
    if finite.size == 0:
        return 0.0, 1.0
    low, high = float(finite.min()), float(finite.max())
    return (low, high) if high > low else (low - 0.5, high + 0.5)


def pixel_extent(shape: tuple[int, int]) -> tuple[float, float, float, float]:
    """The imshow extent that puts pixel (row, col)'s centre at data point (x = col, y = row)."""
    rows, cols = shape
    return -0.5, cols - 0.5, rows - 0.5, -0.5


def map_panel(figure: Figure, axes: Axes, data: ArrayLike, *, title: str, unit: str,
              limits: tuple[float, float] | None = None, cmap: str = SIGNED_CMAP,
              extent: tuple[float, float, float, float] | None = None,
              axis_labels: tuple[str, str] = ("column, px", "row, px")) -> AxesImage:
    """Draw one map in false colour with its colour bar.

    Parameters
    ----------
    figure : Figure
    axes : Axes
    data : array_like, shape (H, W)
        NaN (or inf) outside the aperture: drawn as background.
    title : str
    unit : str
        The colour bar's label, with the unit ("wavefront, waves").
    limits : (float, float), optional
        Colour limits; default: the map's own symmetric limits (:func:`symmetric_limits`).
    cmap : str
        A matplotlib colour map name.
    extent : (left, right, bottom, top), optional
        Data coordinates of the map's outer edges; default: the pixel grid (:func:`pixel_extent`).
    axis_labels : (str, str)
        x and y labels, with their units.

    Returns
    -------
    AxesImage
        Its ``norm`` and ``cmap`` give the colour of any value.
    """
    shown = np.ma.masked_invalid(np.asarray(data, dtype=np.float64))
    low, high = limits if limits is not None else symmetric_limits(data)
    image = axes.imshow(shown, extent=extent or pixel_extent(shown.shape), cmap=cmap,
                        norm=Normalize(low, high), interpolation="nearest")
    axes.set_title(title, fontsize=8)
    axes.set_xlabel(axis_labels[0])
    axes.set_ylabel(axis_labels[1])
    figure.colorbar(image, ax=axes, label=unit, shrink=0.85)
    return image


def aperture_outline(axes: Axes, mask: ArrayLike, extent: tuple[float, float, float, float] | None = None) -> None:
    """Draw the edge of ``mask`` (True inside) as a thin black line, on a map drawn with the same extent."""
    inside = np.asarray(mask, dtype=np.float64)
    if inside.min(initial=1.0) == inside.max(initial=0.0):
        return  # no edge: all inside or all outside
    rows, cols = inside.shape
    left, right, bottom, top = extent or pixel_extent((rows, cols))
    x = np.linspace(left + (right - left) / (2 * cols), right - (right - left) / (2 * cols), cols)
    y = np.linspace(top + (bottom - top) / (2 * rows), bottom - (bottom - top) / (2 * rows), rows)
    axes.contour(x, y, inside, levels=[0.5], colors="black", linewidths=0.8)


def mode_label(j: int, n: int, m: int) -> str:
    """``'Z4 defocus'``: the mode's index in its ordering and its name (``'Z22 (6, 0)'`` when it has none).

    Example
    -------
    >>> mode_label(4, 2, 0)
    'Z4 defocus'
    >>> mode_label(19, 5, -3)
    'Z19 (5, -3)'
    """
    name = mode_name(n, m)
    return f"Z{j} ({n}, {m})" if name.startswith("Z(") else f"Z{j} {name}"


def coefficient_bars(axes: Axes, coefficients: ArrayLike, modes: Sequence[tuple[int, int]], first_index: int, *,
                     unit: str, title: str) -> NDArray[np.float64]:
    """Coefficients as vertical bars named by :func:`mode_label` (at most :data:`MAX_BARS`).

    Parameters
    ----------
    axes : Axes
    coefficients : array_like, shape (M,)
    modes : sequence of (n, m), length M
    first_index : int
        Index of the first mode in its ordering (1 for Noll).
    unit : str
        The coefficients' unit ("waves").
    title : str

    Returns
    -------
    ndarray
        The values drawn: bar ``k`` stands at x = k with height ``values[k]``.
    """
    values = np.asarray(coefficients, dtype=np.float64)[:MAX_BARS]
    shown = len(values)
    positions = np.arange(shown)
    axes.bar(positions, np.nan_to_num(values), width=0.8, color=BAR_COLOUR)
    axes.axhline(0.0, color="black", linewidth=0.6)
    axes.set_xticks(positions, [mode_label(first_index + k, *modes[k]) for k in range(shown)],
                    rotation=90, fontsize=7)
    axes.set_xlim(-0.6, shown - 0.4)
    axes.set_ylabel(f"coefficient, {unit}")
    axes.set_xlabel("mode")
    total = len(np.asarray(coefficients))
    axes.set_title(title + ("" if total == shown else f" (first {shown} of {total})"), fontsize=9)
    axes.grid(axis="y", linewidth=0.3)
    axes.set_axisbelow(True)  # the grid behind the bars
    return values


def mesh_panel(figure: Figure, axes: Axes, points: ArrayLike, triangles: ArrayLike, values: ArrayLike, *,
               norm: Normalize, cmap: str, title: str, unit: str, axis_labels: tuple[str, str],
               edges: bool = True) -> PolyCollection:
    """Draw a triangle mesh, each triangle filled with the colour of its value, with a colour bar.

    Parameters
    ----------
    figure : Figure
    axes : Axes
    points : array_like, shape (V, 2)
        Vertex positions (x, y) in the axes' data units.
    triangles : array_like of int, shape (T, 3)
    values : array_like, shape (T,)
        One value per triangle.
    norm : Normalize
        Value to colour-scale position (a ``Normalize`` or ``LogNorm``).
    cmap : str
    title, unit : str
        The panel's title and the colour bar's label (with the unit).
    axis_labels : (str, str)
    edges : bool
        Also draw the edges, thin and translucent, so the mesh's density shows.

    Returns
    -------
    PolyCollection
        Triangle ``k`` is filled with ``cmap(norm(values[k]))``.
    """
    xy = np.asarray(points, dtype=np.float64)
    tris = np.asarray(triangles)
    filled = axes.tripcolor(xy[:, 0], xy[:, 1], tris, facecolors=np.asarray(values, dtype=np.float64),
                            norm=norm, cmap=cmap, shading="flat")
    if edges:
        axes.triplot(xy[:, 0], xy[:, 1], tris, color="black", linewidth=0.1, alpha=0.35)
    axes.set_aspect("equal")
    axes.set_title(title, fontsize=8)
    axes.set_xlabel(axis_labels[0])
    axes.set_ylabel(axis_labels[1])
    figure.colorbar(filled, ax=axes, label=unit, shrink=0.85)
    return filled
