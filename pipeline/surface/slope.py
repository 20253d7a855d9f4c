"""Surface slope over an integration length, on any measured area, in microradians.

A slope tolerance says over what length the slope is taken: the height difference across the
integration length ``L`` divided by ``L``. Along x at pixel ``j`` (and likewise along y, which
points up, i.e. toward smaller rows)::

    s_x = (z(x_j + L) - z(x_j)) / L

with ``z(x_j + L)`` interpolated linearly between the two pixels that bracket it when ``L`` is
not a whole number of pixels. A slope exists where every pixel it reads is measured; it is
placed at the pixel nearest the middle of its interval. Heights in nm over lengths in mm give
slopes in microradians (1 nm / 1 mm = 1 urad). Mean slopes (tilt: positioning) are removed
before the RMS; the total RMS slope is ``sqrt(rms_x^2 + rms_y^2)``, the RMS of the slope vector.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float
from .area import MeasuredArea

__all__ = ["SlopeFigures", "SlopeMaps", "check_integration_length", "slope_maps"]


@dataclass(frozen=True, eq=False)
class SlopeMaps:
    """x and y slope maps over one integration length, urad, NaN where not defined.

    Attributes
    ----------
    x_urad, y_urad : ndarray, shape (rows, cols)
        Slope along +x (columns) and +y (up), tilt removed.
    length_mm : float
        The integration length.
    """

    x_urad: NDArray[np.float64]
    y_urad: NDArray[np.float64]
    length_mm: float

    def figures(self) -> SlopeFigures:
        """The RMS slopes of these maps."""
        rms_x = _rms(self.x_urad)
        rms_y = _rms(self.y_urad)
        return SlopeFigures(length_mm=self.length_mm, rms_x_urad=rms_x, rms_y_urad=rms_y,
                            rms_urad=math.hypot(rms_x, rms_y),
                            samples=(int(np.count_nonzero(np.isfinite(self.x_urad))),
                                     int(np.count_nonzero(np.isfinite(self.y_urad)))))


@dataclass(frozen=True)
class SlopeFigures:
    """RMS slope over one integration length (tilt removed), urad.

    Attributes
    ----------
    length_mm : float
    rms_x_urad, rms_y_urad : float
    rms_urad : float
        RMS of the slope vector, ``hypot(rms_x, rms_y)``.
    samples : (int, int)
        Slopes that entered each RMS (x, y).
    """

    length_mm: float
    rms_x_urad: float
    rms_y_urad: float
    rms_urad: float
    samples: tuple[int, int]

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"integration_length_mm": self.length_mm, "rms_x_urad": self.rms_x_urad,
                "rms_y_urad": self.rms_y_urad, "rms_urad": self.rms_urad, "samples": list(self.samples)}


def check_integration_length(length_mm: float, pixel_mm: float, extent_mm: float) -> float:
    """The integration length in pixels, or ValueError naming it and what was expected.

    Raises
    ------
    ValueError
        If the length is not a finite number, is shorter than two pixels, or is not shorter
        than the measured area's extent.
    """
    length_mm = positive_float(length_mm, "slope integration length (mm)")
    pixels = length_mm / pixel_mm
    if pixels < 2.0:
        raise ValueError(f"slope integration length {length_mm:g} mm is {pixels:.3g} pixels of {pixel_mm:.4g} mm; "
                         f"expected at least 2 pixels ({2 * pixel_mm:.4g} mm)")
    if length_mm >= extent_mm:
        raise ValueError(f"slope integration length {length_mm:g} mm: expected a length shorter than the measured "
                         f"area ({extent_mm:.4g} mm across)")
    return pixels


def slope_maps(area: MeasuredArea, surface_nm: ArrayLike, pixel_mm: float, length_mm: float) -> SlopeMaps:
    """x and y slope maps of a surface over an integration length.

    Parameters
    ----------
    area : MeasuredArea
    surface_nm : array_like, shape (rows, cols)
        Height in nm, finite on every measured pixel.
    pixel_mm : float
        Pixel pitch (square pixels), mm.
    length_mm : float
        Integration length, mm (at least two pixels).

    Raises
    ------
    ValueError
        For a length shorter than two pixels or not shorter than the area, a map of another
        shape or a non-finite measured pixel.

    Examples
    --------
    A parabola ``z = x^2 / 2`` (nm, x in mm) has slope ``x``: its RMS slope over the disk is
    that of ``x`` (tilt aside), whatever the integration length.

    >>> import numpy as np
    >>> from wavestack.pipeline.surface import measured_area
    >>> rows, cols = np.mgrid[:101, :101]
    >>> x = (cols - 50) * 0.1
    >>> maps = slope_maps(measured_area(np.ones((101, 101), bool)), 0.5 * x**2, 0.1, 0.5)
    >>> round(maps.figures().rms_x_urad, 3), round(maps.figures().rms_y_urad, 3)
    (2.771, 0.0)
    """
    pixel_mm = positive_float(pixel_mm, "pixel_mm")
    pixels = check_integration_length(length_mm, pixel_mm, 2.0 * area.pupil.radius * pixel_mm)
    height = area.scatter(area.values(surface_nm))
    along_x = _difference(height, pixels) / length_mm
    along_y = _difference(height[::-1].T, pixels).T[::-1] / length_mm  # +y is up: toward smaller rows
    if not np.isfinite(along_x).any() and not np.isfinite(along_y).any():
        raise ValueError(f"slope integration length {length_mm:g} mm: no two measured pixels lie that far apart "
                         "along a row or a column; expected a shorter length")
    return SlopeMaps(x_urad=along_x - _mean(along_x), y_urad=along_y - _mean(along_y), length_mm=float(length_mm))


def _difference(height: NDArray[np.float64], pixels: float) -> NDArray[np.float64]:
    """``z(j + pixels) - z(j)`` along rows, interpolated, placed at the middle pixel; NaN where undefined."""
    whole = int(math.floor(pixels))
    fraction = pixels - whole
    cols = height.shape[1]
    reach = whole + (1 if fraction > 0 else 0)
    out = np.full(height.shape, np.nan)
    if reach >= cols:
        return out
    start = height[:, : cols - reach]
    far = height[:, whole: cols - reach + whole]
    if fraction > 0:
        far = (1.0 - fraction) * far + fraction * height[:, whole + 1: cols - reach + whole + 1]
    shift = int(round(pixels / 2))
    out[:, shift: shift + cols - reach] = far - start
    return out


def _mean(values: NDArray[np.float64]) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else 0.0


def _rms(values: NDArray[np.float64]) -> float:
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite * finite))) if finite.size else math.nan
