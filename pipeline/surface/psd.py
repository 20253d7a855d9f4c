"""Power spectral density of a surface measured on any aperture, without filling what was not measured.

Filling unmeasured pixels with a constant puts a step at every edge and drop-out, whose spectrum
falls as ``f^-2`` and hides the surface's own above a few cycles per aperture (prysm issue 45).
Here the map is multiplied by a window that is zero outside the aperture and rises smoothly
inside it (:func:`aperture_window`: a sine-squared taper over the outer tenth of the aperture's
depth, flat inside, so that most measured pixels count in full). The aperture is the
outline of the measured pixels with their drop-outs closed (:func:`aperture_outline`); a hole
larger than a drop-out, such as a central obscuration, is outside it and windowed like the outer
edge. A drop-out is neither windowed (a dip in the window at each would leak the long periods'
power into the short ones) nor filled with a constant: it takes the Gaussian-weighted mean of
the measured pixels around it (the normalised low-pass of :mod:`.areal_filter`, about 2 px wide),
and :attr:`SurfacePsd.interpolated_pixels` counts them.

The map is *prewhitened* before the window: a surface's spectrum falls steeply (``f^-2`` to
``f^-4`` in 2-D), and whatever window is used, its sidelobes carry the long periods' power into
the short ones and bias a fitted slope; the first differences of the map along x and along y
have a spectrum flatter by ``f^2``, which the window leaks far less, and the difference filter's
response is divided out afterwards (prewhitening and recolouring: Percival and Walden [3]_,
section 6.5; Blackman and Tukey). A lighter taper then suffices, which uses more of the measured
pixels and lowers the estimate's scatter. On a grid of spacing ``dx``, with ``d_x`` and ``d_y``
the differences of neighbouring pixels that both lie in the outline, ``w_x`` and ``w_y`` the
geometric mean of the two pixels' window values, each difference field's window-weighted
least-squares plane removed (the map's tilt, power and astigmatism: its quadric, form rather than
texture, whose steep edges the light taper would otherwise leak into every band; a difference has
no piston), and ``F_x``, ``F_y`` the discrete Fourier transforms of ``w_x d_x`` and ``w_y d_y``,

    PSD2(fx, fy) = [|F_x|^2 / sum(w_x^2) + |F_y|^2 / sum(w_y^2)] dx^2 / D(fx, fy)
    D(fx, fy) = 4 sin^2(pi fx dx) + 4 sin^2(pi fy dx)         (nm^2 mm^2, cycles/mm)

(zero at the origin). ``D`` is the power response of a first difference, so ``PSD2 D``
integrates over the frequency plane to the window-weighted mean square of the differences (less
the origin's share). The band-limited RMS is the square root of the integral of ``PSD2`` over
``f_low <= |f| <= f_high``. Below the resolvable band (periods longer than the area, where ``D``
is smallest) the recolouring magnifies what the window spreads there, so ``PSD2`` means nothing
there, and bands reaching into it are refused (:func:`check_band`).
The azimuthally averaged spectrum is the mean of PSD2 over rings of ``|f|`` one frequency step
wide; its 1-D form ``2 pi f <PSD2>`` (nm^2 mm) integrates over ``f`` to the same mean square.

The resolvable band runs from one period across the measured area's largest extent (the
diameter of its enclosing circle) to the Nyquist frequency of the pixel, ``1 / (2 dx)``.

References
----------
.. [1] E. L. Church and P. Z. Takacs, "Surface scattering", in Handbook of Optics (McGraw-Hill,
   1995), vol. I, ch. 7 (PSD conventions, finite-aperture estimates).
.. [2] prysm issue 45, "PSD of data with missing values" (filling corrupts the spectrum).
.. [3] D. B. Percival and A. T. Walden, *Spectral Analysis for Physical Applications*
   (Cambridge University Press, 1993), section 6.5 (prewhitening).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import scipy.fft as fft
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float, real_at_least
from .area import MeasuredArea
from .areal_filter import gaussian_low_pass_at
from .power_law import PowerLaw, fit_power_law

__all__ = ["DROPOUT_CLOSING_PX", "PsdWindow", "SurfacePsd", "aperture_outline", "aperture_window", "check_band",
           "psd_window", "resolvable_band", "surface_psd"]

#: Gaps in the measured pixels up to about twice this width (pixels) are drop-outs, not outline.
DROPOUT_CLOSING_PX = 3
# Drop-outs take the normalised Gaussian low-pass of their neighbours at this cut-off, in units
# of the closing radius (12 px: a weighting function of about 2 px standard deviation).
_DROPOUT_CUTOFF = 4.0
#: The window's taper, as a fraction of the aperture's depth (the largest distance of a pixel to its edge).
TAPER_FRACTION = 0.1


@dataclass(frozen=True, eq=False)
class SurfacePsd:
    """The windowed PSD of one surface.

    Attributes
    ----------
    pixel_mm : float
        Sampling interval, mm.
    fx_per_mm, fy_per_mm : ndarray
        Frequencies of the 2-D spectrum's columns and rows (zero in the middle), cycles/mm.
    psd2_nm2_mm2 : ndarray, shape (len(fy), len(fx))
        The 2-D PSD, nm^2 mm^2 (zero frequency in the middle).
    frequency_per_mm : ndarray, shape (B,)
        Centres of the rings of the azimuthal average, cycles/mm (first: one frequency step).
    azimuthal_nm2_mm2 : ndarray, shape (B,)
        Mean of the 2-D PSD over each ring, nm^2 mm^2.
    resolvable_per_mm : (float, float)
        The band the sampling resolves (see the module notes).
    interpolated_pixels : int
        Drop-outs inside the outline that took their neighbours' weighted mean.
    """

    pixel_mm: float
    fx_per_mm: NDArray[np.float64]
    fy_per_mm: NDArray[np.float64]
    psd2_nm2_mm2: NDArray[np.float64]
    frequency_per_mm: NDArray[np.float64]
    azimuthal_nm2_mm2: NDArray[np.float64]
    resolvable_per_mm: tuple[float, float]
    interpolated_pixels: int = 0

    @property
    def radial_nm2_mm(self) -> NDArray[np.float64]:
        """The 1-D azimuthally integrated PSD ``2 pi f <PSD2>``, nm^2 mm: its integral over f is the mean square."""
        return 2.0 * math.pi * self.frequency_per_mm * self.azimuthal_nm2_mm2

    def band_rms_nm(self, low_per_mm: float, high_per_mm: float) -> float:
        """RMS of the surface between two spatial frequencies (cycles/mm), nm.

        Raises
        ------
        ValueError
            If the band is not inside :attr:`resolvable_per_mm` (the message names it).
        """
        check_band((low_per_mm, high_per_mm), self.resolvable_per_mm)
        fx, fy = np.meshgrid(self.fx_per_mm, self.fy_per_mm)
        radius = np.hypot(fx, fy)
        inside = (radius >= low_per_mm) & (radius <= high_per_mm)
        step = (self.fx_per_mm[1] - self.fx_per_mm[0]) * (self.fy_per_mm[1] - self.fy_per_mm[0])
        return float(math.sqrt(np.sum(self.psd2_nm2_mm2[inside]) * step))

    def power_law(self, low_per_mm: float, high_per_mm: float) -> PowerLaw:
        """The power law ``A f^slope`` fitted to the azimuthal average over a band (see :func:`.power_law.fit_power_law`).

        Raises
        ------
        ValueError
            If the band is not resolvable or holds fewer than three rings.
        """
        check_band((low_per_mm, high_per_mm), self.resolvable_per_mm)
        return fit_power_law(self.frequency_per_mm, self.azimuthal_nm2_mm2, low_per_mm, high_per_mm)


def resolvable_band(area: MeasuredArea, pixel_mm: float) -> tuple[float, float]:
    """(lowest, highest) spatial frequency the area resolves, cycles/mm: 1 / its diameter, 1 / (2 pixel)."""
    pixel_mm = positive_float(pixel_mm, "pixel_mm")
    return 1.0 / (2.0 * area.pupil.radius * pixel_mm), 0.5 / pixel_mm


def check_band(band: tuple[float, float], resolvable: tuple[float, float], name: str = "band") -> None:
    """Refuse a band that is reversed or reaches outside the resolvable one (relative slack 1e-9).

    Raises
    ------
    ValueError
        ``"<name> 0.01-5 cycles/mm: ... expected a band inside 0.0424-4.24 cycles/mm ..."``.
    """
    low, high = (float(v) for v in band)
    lowest, highest = resolvable
    text = f"{name} {low:g}-{high:g} cycles/mm (periods {_period(high)}-{_period(low)} mm)"
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low < high):
        raise ValueError(f"{text}: expected two frequencies 0 < low < high")
    if low < lowest * (1 - 1e-9) or high > highest * (1 + 1e-9):
        raise ValueError(f"{text}: the sampling resolves {lowest:.4g}-{highest:.4g} cycles/mm (one period across "
                         f"the measured area to the pixel's Nyquist frequency); expected a band inside it")


def _period(frequency: float) -> str:
    return f"{1.0 / frequency:.4g}" if frequency > 0 else "inf"


def aperture_outline(valid: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The measured pixels with their drop-outs closed (gaps narrower than about ``2 DROPOUT_CLOSING_PX``).

    A morphological closing by a disk of radius :data:`DROPOUT_CLOSING_PX`: larger holes, such as
    a central obscuration, stay outside the outline.
    """
    size = 2 * DROPOUT_CLOSING_PX + 1
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    margin = DROPOUT_CLOSING_PX + 1
    closed = cv2.morphologyEx(np.pad(valid, margin).astype(np.uint8), cv2.MORPH_CLOSE, disk)
    return closed[margin:-margin, margin:-margin].astype(bool) | valid


def aperture_window(outline: NDArray[np.bool_], taper_px: float | None = None) -> NDArray[np.float64]:
    """The window over an outline: ``sin^2(pi/2 min(d / T, 1))``, zero outside.

    Parameters
    ----------
    outline : ndarray of bool, shape (rows, cols)
        The aperture (:func:`aperture_outline` of the measured pixels).
    taper_px : float, optional
        Taper width ``T``, pixels (at least 0.5); default :data:`TAPER_FRACTION` of the largest
        distance ``d`` of a pixel centre to the outline's edge, and at least 2 pixels. (``T`` equal
        to that largest distance makes the window the aperture's own Hann-like bell.)

    Returns
    -------
    ndarray, shape (rows, cols)
    """
    distance = cv2.distanceTransform(np.pad(outline, 1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    distance = np.maximum(distance[1:-1, 1:-1].astype(np.float64) - 0.5, 0.0)  # to the unmeasured pixel's edge
    if taper_px is None:
        taper = max(TAPER_FRACTION * float(distance.max()), 2.0)
    else:
        taper = real_at_least(taper_px, "taper_px", 0.5)
    return np.where(outline, np.sin(0.5 * math.pi * np.minimum(distance / max(taper, 0.5), 1.0)) ** 2, 0.0)


@dataclass(frozen=True, eq=False)
class PsdWindow:
    """What the PSD of maps on one area reuses: the outline, its window and the drop-outs.

    Attributes
    ----------
    outline : ndarray of bool, shape (rows, cols)
        :func:`aperture_outline` of the measured pixels.
    window : ndarray, shape (rows, cols)
        :func:`aperture_window` of the outline.
    dropouts : (ndarray, ndarray)
        Rows and columns of the outline's pixels without a measurement.
    """

    outline: NDArray[np.bool_]
    window: NDArray[np.float64]
    dropouts: tuple[NDArray[np.int64], NDArray[np.int64]]


def psd_window(area: MeasuredArea) -> PsdWindow:
    """The outline, window and drop-outs of an area (see the module notes)."""
    outline = aperture_outline(area.valid)
    return PsdWindow(outline=outline, window=aperture_window(outline), dropouts=np.nonzero(outline & ~area.valid))


def surface_psd(area: MeasuredArea, surface_nm: ArrayLike, pixel_mm: float, *,
                window: PsdWindow | None = None) -> SurfacePsd:
    """The windowed PSD of a surface on its measured area.

    Parameters
    ----------
    area : MeasuredArea
    surface_nm : array_like, shape (rows, cols)
        Surface height, nm; finite on every measured pixel.
    pixel_mm : float
        Sampling interval (square pixels), mm.
    window : PsdWindow, optional
        :func:`psd_window` of the area, when the caller keeps it across maps.

    Returns
    -------
    SurfacePsd

    Raises
    ------
    ValueError
        For a non-positive pixel, a map of another shape, a non-finite measured pixel, or an area
        without two neighbouring pixels.

    Examples
    --------
    A sinusoid of 2 nm amplitude and 4 mm period on a disk of 0.5 mm pixels: its band holds
    its RMS, 2 / sqrt(2) nm.

    >>> import numpy as np
    >>> from wavestack.pipeline.surface import measured_area
    >>> rows, cols = np.mgrid[:128, :128]
    >>> disk = (rows - 63.5) ** 2 + (cols - 63.5) ** 2 <= 60**2
    >>> psd = surface_psd(measured_area(disk), 2 * np.sin(2 * np.pi * cols * 0.5 / 4), 0.5)
    >>> round(psd.band_rms_nm(0.15, 0.35), 2)
    1.41
    """
    pixel_mm = positive_float(pixel_mm, "pixel_mm")
    values = area.values(surface_nm)
    window = psd_window(area) if window is None else window
    rows, cols = np.nonzero(area.valid)
    gap_rows, gap_cols = window.dropouts
    if gap_rows.size:
        filled = gaussian_low_pass_at(rows, cols, values, _DROPOUT_CUTOFF * DROPOUT_CLOSING_PX, at=window.dropouts)
        rows, cols = np.concatenate([rows, gap_rows]), np.concatenate([cols, gap_cols])
        values = np.concatenate([values, filled])
    top, left = rows.min(), cols.min()
    box = (int(rows.max() - top + 1), int(cols.max() - left + 1))
    heights, weights, inside = np.zeros(box), np.zeros(box), np.zeros(box, bool)
    heights[rows - top, cols - left] = values
    weights[rows - top, cols - left] = window.window[rows, cols]
    inside[rows - top, cols - left] = True
    shape = (fft.next_fast_len(box[0]), fft.next_fast_len(box[1]))
    fy = fft.fftfreq(shape[0], pixel_mm)
    fx = fft.fftfreq(shape[1], pixel_mm)
    spectrum, response = _prewhitened_spectrum(heights, weights, inside, shape, fx * pixel_mm, fy * pixel_mm)
    with np.errstate(divide="ignore", invalid="ignore"):
        recoloured = np.where(response > 1e-12, spectrum / response, 0.0) * pixel_mm**2
    spectrum = fft.fftshift(recoloured)
    fy, fx = fft.fftshift(fy), fft.fftshift(fx)
    centres, means = _azimuthal_mean(fx, fy, spectrum)
    return SurfacePsd(pixel_mm=pixel_mm, fx_per_mm=fx, fy_per_mm=fy, psd2_nm2_mm2=spectrum,
                      frequency_per_mm=centres, azimuthal_nm2_mm2=means,
                      resolvable_per_mm=resolvable_band(area, pixel_mm), interpolated_pixels=int(gap_rows.size))


def _prewhitened_spectrum(heights: NDArray[np.float64], weights: NDArray[np.float64], inside: NDArray[np.bool_],
                          shape: tuple[int, int], fx_per_px: NDArray[np.float64],
                          fy_per_px: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The summed, normalised periodograms of the windowed first differences along x and y, and the
    differences' power response ``D`` on the same (unshifted) grid (module notes).

    Raises
    ------
    ValueError
        If no two neighbouring pixels lie in the outline along either axis.
    """
    spectrum, response = np.zeros(shape), np.zeros(shape)
    for axis, frequency in ((0, fy_per_px[:, None]), (1, fx_per_px[None, :])):
        ahead = [slice(None), slice(None)]
        behind = [slice(None), slice(None)]
        ahead[axis], behind[axis] = slice(1, None), slice(None, -1)
        pairs = inside[tuple(ahead)] & inside[tuple(behind)]
        pair_weights = np.where(pairs, np.sqrt(weights[tuple(ahead)] * weights[tuple(behind)]), 0.0)
        total = float(np.sum(pair_weights**2))
        if total <= 0:
            continue
        differences = heights[tuple(ahead)] - heights[tuple(behind)]
        differences = differences - _weighted_plane_on(differences, pair_weights**2, pairs)  # the map's quadric
        field = np.zeros(shape)
        field[: differences.shape[0], : differences.shape[1]] = pair_weights * differences
        spectrum += np.abs(fft.fft2(field)) ** 2 / total
        response = response + 4.0 * np.sin(np.pi * frequency) ** 2
    if not np.any(response):
        raise ValueError("PSD: the measured area holds no two neighbouring pixels; expected an area at least "
                         "two pixels wide")
    return spectrum, response


def _weighted_plane_on(values: NDArray[np.float64], weights: NDArray[np.float64],
                       where: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The weighted least-squares plane through ``values`` at the pixels ``where``, over the whole grid."""
    rows, cols = np.nonzero(where)
    design = np.column_stack([np.ones(rows.size), cols - cols.mean(), rows - rows.mean()])
    root = np.sqrt(weights[rows, cols])
    solution, *_ = np.linalg.lstsq(design * root[:, None], values[rows, cols] * root, rcond=None)
    grid_rows, grid_cols = np.indices(values.shape)
    return solution[0] + solution[1] * (grid_cols - cols.mean()) + solution[2] * (grid_rows - rows.mean())


def _azimuthal_mean(fx: NDArray[np.float64], fy: NDArray[np.float64],
                    spectrum: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean of the spectrum over rings one frequency step wide, centred on multiples of the step."""
    step = max(fx[1] - fx[0], fy[1] - fy[0])
    radius = np.hypot(*np.meshgrid(fx, fy))
    ring = np.rint(radius / step).astype(np.int64).ravel()
    rings = int(min(np.abs(fx).max(), np.abs(fy).max()) / step)
    keep = (ring >= 1) & (ring <= rings)
    sums = np.bincount(ring[keep], weights=spectrum.ravel()[keep], minlength=rings + 1)[1:]
    counts = np.bincount(ring[keep], minlength=rings + 1)[1:]
    filled = counts > 0
    return np.arange(1, rings + 1)[filled] * step, sums[filled] / counts[filled]
