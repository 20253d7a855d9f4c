"""Areal Gaussian filters (ISO 16610-21's transmission), normalised inside the measured area.

The Gaussian low-pass of cut-off wavelength ``lc`` transmits a sinusoid of wavelength ``l`` by

    T(l) = exp(-pi (alpha lc / l)^2),   alpha = sqrt(ln 2 / pi)

so exactly half at the cut-off (ISO 16610-21, the profile filter; ISO 16610-61 uses the same
transmission areally). Its weighting function is ``exp(-pi (r / (alpha lc))^2) / (alpha lc)^2``.
The high-pass is the map less its low-pass; the band-pass ``bp:ls,lc`` is the low-pass at the
short cut-off ``ls`` less the low-pass at the long one ``lc``, so it passes the wavelengths
between them with half at each cut-off (when they lie far apart).

Inside an aperture the low-pass is a normalised convolution: the filtered map times the mask
divided by the filtered mask, so a pixel near the edge is the Gaussian-weighted mean of the
measured pixels around it and is not pulled toward zero by the pixels that were not measured.
It is exact for a constant everywhere and for any map where the whole weighting function lies
inside the area; within about one cut-off of the edge the weights are one-sided and the
transmission is no longer the Gaussian's. The convolution is a product of Fourier transforms
with the transfer function above, on a grid padded so that no pixel reaches round onto another.

References
----------
.. [1] ISO 16610-21:2011, Geometrical product specifications (GPS) - Filtration - Part 21:
   Linear profile filters: Gaussian filters.
.. [2] ISO 16610-61:2015, Part 61: Linear areal filters: Gaussian filters.
.. [3] H. Knutsson and C.-F. Westin, "Normalized and differential convolution", CVPR 1993.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import scipy.fft as fft
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float
from .area import MeasuredArea

__all__ = ["ALPHA", "ArealFilter", "filter_surface", "gaussian_transmission", "parse_areal_filter"]

#: The Gaussian filter's constant: transmission 50 % at the cut-off.
ALPHA = math.sqrt(math.log(2.0) / math.pi)
# The weighting function at 3.2 alpha lc is exp(-pi 3.2^2) = 1e-14 of its peak: the grid is
# padded by this much (at most the map's own size, beyond which the kernel is 6e-7 or less
# for every cut-off the area resolves).
_REACH = 3.2
# A normalisation below this (the weighting function's reach is 1e-14 of its peak) means no
# known pixel is near: the low-pass is undefined there.
_UNREACHED = 1e-9
_FILTER = re.compile(r"^\s*(lp|hp|bp)\s*:\s*([^,\s]+)\s*(?:,\s*([^,\s]+)\s*)?$", re.IGNORECASE)
_KINDS = {"lp": "low-pass", "hp": "high-pass", "bp": "band-pass"}


@dataclass(frozen=True)
class ArealFilter:
    """A Gaussian areal filter.

    Attributes
    ----------
    kind : {"lp", "hp", "bp"}
        Low-, high- or band-pass.
    cutoffs_mm : tuple of float
        ``(lc,)`` for lp and hp; ``(ls, lc)`` with ``ls < lc`` for bp, mm.
    """

    kind: str
    cutoffs_mm: tuple[float, ...]

    def describe(self) -> str:
        """E.g. ``"band-pass 0.5-5 mm"``."""
        return f"{_KINDS[self.kind]} {'-'.join(f'{c:g}' for c in self.cutoffs_mm)} mm"

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"kind": self.kind, "cutoffs_mm": list(self.cutoffs_mm)}

    def check_resolvable(self, pixel_mm: float, extent_mm: float) -> None:
        """Refuse a cut-off shorter than two pixels or longer than the measured area.

        Raises
        ------
        ValueError
            Naming the filter, the cut-off and the range expected.
        """
        for cutoff in self.cutoffs_mm:
            if cutoff < 2.0 * pixel_mm or cutoff > extent_mm:
                raise ValueError(
                    f"filter {self.kind}:{','.join(f'{c:g}' for c in self.cutoffs_mm)}: cut-off {cutoff:g} mm is "
                    f"outside what the sampling resolves; expected {2 * pixel_mm:.4g} mm (two pixels) to "
                    f"{extent_mm:.4g} mm (the measured area's extent)")


def parse_areal_filter(text: str) -> ArealFilter:
    """Read ``lp:LC``, ``hp:LC`` or ``bp:LS,LC`` (cut-off wavelengths in mm).

    Raises
    ------
    ValueError
        Naming the text and the form expected.

    Examples
    --------
    >>> parse_areal_filter("bp:0.5,5").describe()
    'band-pass 0.5-5 mm'
    """
    expected = "expected lp:CUTOFF_MM, hp:CUTOFF_MM or bp:SHORT_MM,LONG_MM with cut-offs > 0, e.g. 'bp:0.5,5'"
    found = _FILTER.match(text) if isinstance(text, str) else None
    if found is None:
        raise ValueError(f"filter {text!r}: {expected}")
    kind = found.group(1).lower()
    try:
        cutoffs = tuple(float(v) for v in found.groups()[1:] if v is not None)
    except ValueError:
        raise ValueError(f"filter {text!r}: {expected}") from None
    if len(cutoffs) != (2 if kind == "bp" else 1) or not all(math.isfinite(c) and c > 0 for c in cutoffs):
        raise ValueError(f"filter {text!r}: {expected}")
    if kind == "bp" and not cutoffs[0] < cutoffs[1]:
        raise ValueError(f"filter {text!r}: a band-pass needs the short cut-off before the long one; {expected}")
    return ArealFilter(kind=kind, cutoffs_mm=cutoffs)


def gaussian_transmission(wavelength_mm: ArrayLike, cutoff_mm: float) -> NDArray[np.float64]:
    """The low-pass transmission ``exp(-pi (alpha lc / l)^2)`` of sinusoids of wavelength ``l``.

    >>> float(gaussian_transmission(2.0, 2.0))
    0.5
    """
    return _transfer(1.0 / np.asarray(wavelength_mm, dtype=np.float64), cutoff_mm)


def _transfer(frequency: NDArray[np.float64], cutoff: float) -> NDArray[np.float64]:
    """The low-pass transfer function at spatial frequency ``frequency`` (1 / the cut-off's unit)."""
    return np.exp(-math.pi * (ALPHA * cutoff * frequency) ** 2)


def filter_surface(area: MeasuredArea, surface_nm: ArrayLike, pixel_mm: float,
                   areal_filter: ArealFilter) -> NDArray[np.float64]:
    """The filtered surface on the measured area (NaN elsewhere), in the surface's units.

    Parameters
    ----------
    area : MeasuredArea
    surface_nm : array_like, shape (rows, cols)
        Finite on every measured pixel.
    pixel_mm : float
        Pixel pitch (square pixels), mm.
    areal_filter : ArealFilter

    Raises
    ------
    ValueError
        For a cut-off outside two pixels to the area's extent, a map of another shape or a
        non-finite measured pixel.

    Examples
    --------
    A constant is kept to the edge (the normalisation); a wave of a quarter of the cut-off is
    removed where the weighting function lies inside the disk (2^-16 of it is left):

    >>> import numpy as np
    >>> from wavestack.pipeline.surface import measured_area
    >>> rows, cols = np.mgrid[:96, :96]
    >>> r2 = (rows - 47.5) ** 2 + (cols - 47.5) ** 2
    >>> area, lp16 = measured_area(r2 <= 45**2), parse_areal_filter("lp:16")
    >>> bool(np.allclose(filter_surface(area, np.full((96, 96), 5.0), 1.0, lp16)[r2 <= 45**2], 5.0))
    True
    >>> wave = filter_surface(area, np.sin(2 * np.pi * cols / 4.0), 1.0, lp16)
    >>> bool(np.abs(wave[r2 <= 25**2]).max() < 2e-5)
    True
    """
    pixel_mm = positive_float(pixel_mm, "pixel_mm")
    areal_filter.check_resolvable(pixel_mm, 2.0 * area.pupil.radius * pixel_mm)
    values = area.values(surface_nm)
    rows, cols = np.nonzero(area.valid)
    lows = [gaussian_low_pass_at(rows, cols, values, cutoff / pixel_mm) for cutoff in areal_filter.cutoffs_mm]
    if areal_filter.kind == "lp":
        result = lows[0]
    elif areal_filter.kind == "hp":
        result = values - lows[0]
    else:
        result = lows[0] - lows[1]
    return area.scatter(result)


def gaussian_low_pass_at(rows: NDArray[np.int64], cols: NDArray[np.int64], values: NDArray[np.float64],
                         cutoff_px: float, at: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
                         ) -> NDArray[np.float64]:
    """The normalised Gaussian low-pass of values known at some pixels, evaluated at pixels ``at``.

    Parameters
    ----------
    rows, cols : ndarray of int, shape (N,)
        Where the values are known.
    values : ndarray, shape (N,)
    cutoff_px : float
        Cut-off wavelength, pixels.
    at : (rows, cols), optional
        Where to evaluate (default: the known pixels); each must have a known pixel within
        reach of the weighting function, or the result there is NaN.

    Returns
    -------
    ndarray, shape of ``at``
    """
    at_rows, at_cols = (rows, cols) if at is None else at
    top, left = min(rows.min(), at_rows.min()), min(cols.min(), at_cols.min())
    height = int(max(rows.max(), at_rows.max()) - top + 1)
    width = int(max(cols.max(), at_cols.max()) - left + 1)
    pad = int(math.ceil(_REACH * ALPHA * cutoff_px))
    shape = (fft.next_fast_len(height + min(pad, height)), fft.next_fast_len(width + min(pad, width)))
    transfer = _transfer(np.hypot(*np.meshgrid(fft.rfftfreq(shape[1]), fft.fftfreq(shape[0]))), cutoff_px)
    data = np.zeros(shape)
    weight = np.zeros(shape)
    data[rows - top, cols - left] = values
    weight[rows - top, cols - left] = 1.0
    smooth_data = fft.irfft2(fft.rfft2(data) * transfer, shape)[at_rows - top, at_cols - left]
    smooth_weight = fft.irfft2(fft.rfft2(weight) * transfer, shape)[at_rows - top, at_cols - left]
    reached = smooth_weight > _UNREACHED
    return np.where(reached, smooth_data / np.where(reached, smooth_weight, 1.0), np.nan)
