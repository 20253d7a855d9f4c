"""PVr, Evans' robust peak-to-valley: the PV of a 36-term Fringe Zernike fit plus 3x its residual RMS.

The PV of a measured map follows its worst pixel (a spike, a speck of dust, a rim pixel with a
wrong fringe order); PVr follows the surface. Evans defines it as the peak-to-valley of the
36-term Fringe Zernike fit to the map plus three times the RMS of the fit's residual. Here the
fit is least squares over the measured pixels themselves, on the circle that encloses them, after
piston and tilt (positioning) are removed; the PV of the fitted surface is taken over the same
pixels. (prysm's ``pvr()`` refuses non-square data and evaluates its fit on a grid of its own.)

The fit is the project's fitter (``build_fitter``, the 36 Fringe terms over the enclosing
circle orthonormalised on the measured pixels: method ``qr``, whose fitted surface is the
circle polynomials' least-squares fit however poorly they are conditioned on the area, e.g. a
long strip), built once per measured area; every command that reports PVr (analyze, fit, the
station, polishing, the instrument processors) calls :class:`RobustPVAnalyzer` for it. A map
that left some of the area's pixels out (an interferometer's data-quality mask, spike clipping)
is measured on the rest without a new fitter (``nan_policy="omit"``: the fitter's downdate).

References
----------
.. [1] C. J. Evans, "PVr - a robust amplitude parameter for optical surface specification",
   Opt. Eng. 48(4), 043605 (2009).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, DTypeLike

from ..aperture import Aperture
from ..fit import build_fitter
from .area import MeasuredArea

__all__ = ["PVR_MODES", "RobustPV", "RobustPVAnalyzer"]

#: The number of Fringe Zernike terms of Evans' definition (up to Z36, radial order 10).
PVR_MODES = 36


@dataclass(frozen=True)
class RobustPV:
    """PVr and its two parts, in the map's units.

    Attributes
    ----------
    pvr : float
        ``fit_pv + 3 * residual_rms``.
    fit_pv : float
        Peak-to-valley of the fitted 36-term surface over the measured pixels.
    residual_rms : float
        RMS of the map less the fit (and less piston and tilt) over the measured pixels.
    """

    pvr: float
    fit_pv: float
    residual_rms: float


class RobustPVAnalyzer:
    """PVr of maps measured on one area (the fitter is built once).

    Parameters
    ----------
    area : MeasuredArea
    remove : {"ptt", "pttp"} or None
        The physical terms removed before the fit (the figures of a map reported less power
        remove power too); default piston and tilt.
    dtype : numpy dtype
        The fit's dtype (float64; float32 halves the stored operator of a large area).

    Raises
    ------
    IllConditionedBasis
        If the area cannot carry the 36 terms.

    Examples
    --------
    Primary spherical aberration plus one spike: PV follows the spike, PVr does not.

    >>> import numpy as np
    >>> from wavestack.pipeline.surface import measured_area
    >>> rows, cols = np.mgrid[:65, :65]
    >>> x, y = (cols - 32) / 32, (32 - rows) / 32
    >>> disk = x**2 + y**2 <= 1
    >>> surface = 10 * (6 * (x**2 + y**2) ** 2 - 6 * (x**2 + y**2) + 1)
    >>> surface[32, 40] += 500.0
    >>> pvr = RobustPVAnalyzer(measured_area(disk)).measure(surface)
    >>> round(float(np.ptp(surface[disk]))), round(pvr.pvr)
    (511, 44)
    """

    def __init__(self, area: MeasuredArea, *, remove: str | None = "ptt", dtype: DTypeLike = np.float64) -> None:
        self.area = area
        self._fitter = build_fitter(Aperture.from_mask(area.valid), method="qr", modes=PVR_MODES,
                                    ordering="fringe", pupil=area.pupil, dtype=dtype, remove=remove)

    def measure(self, surface: ArrayLike, *, nan_policy: str = "raise") -> RobustPV:
        """PVr of a map.

        Parameters
        ----------
        surface : array_like, shape (rows, cols)
            Finite on every measured pixel (or NaN where left out, with ``nan_policy="omit"``);
            pixels off the area are ignored. Any unit.
        nan_policy : {"raise", "omit"}
            ``"omit"``: the area's pixels that are not finite are left out of the fit and of the
            fitted surface's PV.

        Raises
        ------
        ValueError
            If the map's shape differs from the area's, or a measured pixel is not finite and
            ``nan_policy`` is ``"raise"``.
        InvalidFrame
            If too few finite pixels are left to fit (``"omit"``).
        """
        surface = np.asarray(surface)
        if nan_policy == "raise":
            self.area.values(surface)  # every measured pixel finite, the shape the area's
        elif surface.shape != self.area.shape:
            raise ValueError(f"surface: expected a map of shape {self.area.shape}, got {surface.shape}")
        result = self._fitter.fit(surface, nan_policy=nan_policy)  # the fitter reads the measured pixels only
        fitted = self._fitter.surface(result.coefficients)
        used = fitted[np.isfinite(surface) & self.area.valid]
        fit_pv = float(used.max() - used.min())
        return RobustPV(pvr=fit_pv + 3.0 * result.residual_rms, fit_pv=fit_pv, residual_rms=result.residual_rms)
