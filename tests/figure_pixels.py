"""Reading a saved figure back: the pixel at a data point of an axes, and the colour a value should have.

A figure saved by :func:`wavestack.figures.save_figure` is a PNG of the figure's own size, so a
point's display coordinates (``axes.transData``, origin at the bottom left) name a pixel of the
file (origin at the top left). Comparing that pixel with the colour the data value maps to checks
that the figure shows the data, not merely that a file exists.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.image
import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import Normalize, to_rgb
from matplotlib.figure import Figure

from wavestack.figures import DPI, save_figure

# Agg writes 8-bit channels: a colour survives the round trip to within 1/255 per channel; 2.5/255
# also covers the rounding of a value that sits exactly on a colour-map step.
TOLERANCE = 2.5 / 255


def saved(figure: Figure, path: Path) -> np.ndarray:
    """Save ``figure`` and read it back as an (H, W, 3) float array in [0, 1]; checks its pixel size."""
    save_figure(figure, path)
    image = matplotlib.image.imread(path)
    width, height = figure.get_size_inches()
    assert image.shape[:2] == (round(height * DPI), round(width * DPI)), image.shape
    return image[..., :3]


def pixel(image: np.ndarray, axes: Axes, x: float, y: float) -> np.ndarray:
    """The RGB pixel of ``image`` at data point (x, y) of ``axes``."""
    column, up = axes.transData.transform((x, y))
    row = image.shape[0] - up
    assert 0 <= row < image.shape[0] and 0 <= column < image.shape[1], (x, y, row, column)
    return image[int(row), int(column)]


def colour(cmap: str, norm: Normalize, value: float) -> np.ndarray:
    """The RGB colour ``value`` takes under ``cmap`` and ``norm``."""
    return np.asarray(matplotlib.colormaps[cmap](norm(value)))[:3]


def assert_colour(found: np.ndarray, expected: np.ndarray | str, what: str) -> None:
    """``found`` is ``expected`` (an RGB array or a matplotlib colour name) to 8-bit rounding."""
    want = np.asarray(to_rgb(expected)) if isinstance(expected, str) else np.asarray(expected)
    assert np.max(np.abs(found - want)) <= TOLERANCE, f"{what}: pixel {found}, expected {want}"


def near(image: np.ndarray, axes: Axes, x: float, y: float, expected: str, radius: int = 3) -> bool:
    """True when a pixel within ``radius`` of data point (x, y) has the colour ``expected`` (a line's)."""
    column, up = axes.transData.transform((x, y))
    row, column = int(image.shape[0] - up), int(column)
    window = image[max(row - radius, 0): row + radius + 1, max(column - radius, 0): column + radius + 1]
    return bool(np.any(np.max(np.abs(window - np.asarray(to_rgb(expected))), axis=-1) <= 12 / 255))
