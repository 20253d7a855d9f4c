"""The tool influence function (TIF): the removal rate a tool dwelling at one point leaves around it.

Removal is the TIF convolved with the dwell-time map (Preston's law, removal rate = k P v; Jones,
Appl. Opt. 16, 218, 1977). Here the TIF is a kernel on the camera's pixel grid in nm of removal
per second of dwell at the kernel's centre pixel; :func:`~.removal.removal_nm` does the
convolution.
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float, real_image
from ._inputs import read_only

logger = logging.getLogger(__name__)

FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
"""FWHM = 2 sqrt(2 ln 2) sigma, about 2.3548, for a Gaussian."""

DEFAULT_TRUNCATE_SIGMA = 3.0
"""The Gaussian kernel is cut at 3 sigma, where it has fallen to exp(-4.5) ~ 1.1 % of its peak;
the cut drops ~1.1 % of the removal volume, spread so thinly that it is nearly a piston."""


@dataclass(frozen=True)
class ToolInfluence:
    """A tool influence function sampled on the grid: removal rate in nm/s around the tool.

    Attributes
    ----------
    kernel_nm_per_s : NDArray[np.float64], shape (2r+1, 2r+1)
        Removal rate (nm of surface per second of dwell) at each offset from the tool, the tool
        at the centre pixel ``[r, r]``; finite and >= 0, not all zero. Read-only.
    pixel_mm : float
        Grid pixel size on the optic (mm).
    kind : str
        ``"gaussian"`` or ``"map"`` (measured).
    fwhm_mm : float or None
        Full width at half maximum of a Gaussian TIF (mm); None for a measured map.
    truncate_sigma : float or None
        Radius, in sigmas, where a Gaussian kernel was cut; None for a measured map.

    Raises
    ------
    ValueError
        Naming ``kernel_nm_per_s`` (not a square odd-sized 2-D array of finite values >= 0
        with a positive sum) or ``pixel_mm`` (not > 0).

    Examples
    --------
    >>> from wavestack.pipeline.polishing import ToolInfluence
    >>> tif = ToolInfluence.gaussian(fwhm_mm=3.0, peak_rate_nm_s=2.0, pixel_mm=0.2)
    >>> tif.kernel_nm_per_s.shape, tif.radius_px
    ((39, 39), 19)
    >>> float(tif.kernel_nm_per_s[19, 19]), round(float(tif.kernel_nm_per_s[19, 26]), 2)  # FWHM 15 px
    (2.0, 1.09)
    """

    kernel_nm_per_s: NDArray[np.float64]
    pixel_mm: float
    kind: str = "map"
    fwhm_mm: float | None = None
    truncate_sigma: float | None = None
    _footprint: NDArray[np.bool_] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        kernel = np.asarray(real_image(self.kernel_nm_per_s, "kernel_nm_per_s"), dtype=np.float64)
        rows, cols = kernel.shape
        if rows != cols or rows % 2 == 0:
            raise ValueError(f"kernel_nm_per_s: expected a square odd-sized kernel (2r+1, 2r+1), got {kernel.shape}")
        if not np.all(np.isfinite(kernel)):
            raise ValueError("kernel_nm_per_s: expected finite values, got NaN or inf")
        if np.any(kernel < 0):
            raise ValueError(f"kernel_nm_per_s: expected removal rates >= 0, got a minimum of {kernel.min():.3g}")
        if not kernel.sum() > 0:
            raise ValueError("kernel_nm_per_s: expected a kernel with a positive removal rate somewhere, got all zero")
        object.__setattr__(self, "pixel_mm", positive_float(self.pixel_mm, "pixel_mm"))
        object.__setattr__(self, "kernel_nm_per_s", read_only(kernel))
        object.__setattr__(self, "_footprint", read_only(kernel > 0))

    @classmethod
    def gaussian(
        cls,
        fwhm_mm: float,
        peak_rate_nm_s: float,
        pixel_mm: float,
        *,
        truncate_sigma: float = DEFAULT_TRUNCATE_SIGMA,
    ) -> ToolInfluence:
        """A round Gaussian TIF, ``peak * exp(-rho^2 / (2 sigma^2))``, cut at ``truncate_sigma``.

        Parameters
        ----------
        fwhm_mm : float
            Full width at half maximum (mm), > 0; sigma = FWHM / (2 sqrt(2 ln 2)).
        peak_rate_nm_s : float
            Removal rate at the tool centre (nm/s), > 0.
        pixel_mm : float
            Grid pixel size (mm), > 0.
        truncate_sigma : float, optional
            Cut radius in sigmas (default 3); the kernel is zero beyond it, so its footprint is
            a disc and the dwell grid grows by that disc.

        Returns
        -------
        ToolInfluence
            Kernel of radius ``r = floor(truncate_sigma * sigma / pixel_mm)`` pixels.

        Raises
        ------
        ValueError
            Naming ``fwhm_mm``, ``peak_rate_nm_s``, ``pixel_mm`` or ``truncate_sigma`` when not > 0.
        """
        fwhm = positive_float(fwhm_mm, "fwhm_mm")
        peak = positive_float(peak_rate_nm_s, "peak_rate_nm_s")
        pixel = positive_float(pixel_mm, "pixel_mm")
        cut = positive_float(truncate_sigma, "truncate_sigma")
        sigma_px = fwhm / FWHM_PER_SIGMA / pixel
        radius = int(math.floor(cut * sigma_px))
        offsets = np.arange(-radius, radius + 1, dtype=np.float64)
        rho2 = offsets[:, None] ** 2 + offsets[None, :] ** 2
        kernel = peak * np.exp(-rho2 / (2.0 * sigma_px**2))
        kernel[rho2 > (cut * sigma_px) ** 2] = 0.0
        return cls(kernel, pixel, kind="gaussian", fwhm_mm=fwhm, truncate_sigma=cut)

    @classmethod
    def from_map(cls, array: ArrayLike, pixel_mm: float, *, peak_rate_nm_s: float | None = None) -> ToolInfluence:
        """A measured TIF: removal rate per pixel (nm/s) around the tool, from an array.

        An odd-sized map is taken as centred on its middle pixel (the usual way to store a TIF).
        An even-sized map has no middle pixel: it is re-centred on its removal-weighted centroid
        (rounded to a pixel), which is the tool centre of a symmetric tool. Either way the result
        is padded to a square and trimmed to the smallest square around the non-zero removal.

        Parameters
        ----------
        array : array_like, shape (h, w)
            Removal rate (nm/s); finite, >= 0 (clip the noise floor of a measurement first), not
            all zero.
        pixel_mm : float
            The grid pixel size the map is sampled at (mm), > 0 (resample a TIF measured at
            another scale before).
        peak_rate_nm_s : float, optional
            Scale the map so that its maximum is this rate (nm/s); kept as measured if None.

        Raises
        ------
        ValueError
            Naming ``array`` (not 2-D, not finite, negative, all zero), ``pixel_mm`` or
            ``peak_rate_nm_s``.
        """
        rates = np.asarray(real_image(array, "array"), dtype=np.float64)
        if not np.all(np.isfinite(rates)):
            raise ValueError(f"array: expected a TIF map of finite values, got {np.count_nonzero(~np.isfinite(rates))} NaN or inf")
        if np.any(rates < 0):
            raise ValueError(f"array: expected removal rates >= 0, got a minimum of {rates.min():.3g} nm/s")
        if not rates.sum() > 0:
            raise ValueError("array: expected some removal, got an all-zero TIF map")
        if peak_rate_nm_s is not None:
            rates = rates * (positive_float(peak_rate_nm_s, "peak_rate_nm_s") / rates.max())
        return cls(_centred_square(rates), pixel_mm, kind="map")

    @property
    def radius_px(self) -> int:
        """Kernel half-width r (pixels): the kernel is (2r+1, 2r+1)."""
        return self.kernel_nm_per_s.shape[0] // 2

    @property
    def footprint(self) -> NDArray[np.bool_]:
        """Where the kernel removes anything, bool (2r+1, 2r+1), read-only."""
        return self._footprint

    @property
    def peak_rate_nm_s(self) -> float:
        """Largest removal rate in the kernel (nm/s)."""
        return float(self.kernel_nm_per_s.max())

    @property
    def volume_rate_nm_px_s(self) -> float:
        """Kernel sum (nm px^2 / s): the uniform removal rate of a uniform 1 s/pixel dwell."""
        return float(self.kernel_nm_per_s.sum())

    def as_dict(self) -> dict[str, Any]:
        """A plain-JSON description (for a job file's ``tif`` field).

        Gaussian: kind, fwhm_mm, peak_rate_nm_s, pixel_mm, radius_px, truncate_sigma. Map: kind,
        peak_rate_nm_s, pixel_mm, radius_px, volume_rate_nm_mm2_s and the SHA-256 of the kernel's
        float64 bytes.
        """
        described: dict[str, Any] = {
            "kind": self.kind,
            "peak_rate_nm_s": self.peak_rate_nm_s,
            "pixel_mm": self.pixel_mm,
            "radius_px": self.radius_px,
            "volume_rate_nm_mm2_s": self.volume_rate_nm_px_s * self.pixel_mm**2,
        }
        if self.kind == "gaussian":
            described.update(fwhm_mm=self.fwhm_mm, truncate_sigma=self.truncate_sigma)
        else:
            described["kernel_sha256"] = hashlib.sha256(np.ascontiguousarray(self.kernel_nm_per_s).tobytes()).hexdigest()
        return described


def _centred_square(rates: NDArray[np.float64]) -> NDArray[np.float64]:
    """The map on a (2r+1, 2r+1) square centred on its tool pixel, trimmed to the non-zero part."""
    rows, cols = rates.shape
    if rows % 2 and cols % 2:
        centre = (rows // 2, cols // 2)
    else:
        grid_r, grid_c = np.indices(rates.shape)
        total = rates.sum()
        centre = (int(round(float((grid_r * rates).sum() / total))), int(round(float((grid_c * rates).sum() / total))))
        logger.info("TIF map of even shape %s re-centred on its centroid pixel %s", rates.shape, centre)
    nz_r, nz_c = np.nonzero(rates)
    radius = int(max(np.abs(nz_r - centre[0]).max(), np.abs(nz_c - centre[1]).max()))
    square = np.zeros((2 * radius + 1, 2 * radius + 1))
    r0, c0 = max(centre[0] - radius, 0), max(centre[1] - radius, 0)
    r1, c1 = min(centre[0] + radius + 1, rows), min(centre[1] + radius + 1, cols)
    square[r0 - centre[0] + radius : r1 - centre[0] + radius, c0 - centre[1] + radius : c1 - centre[1] + radius] = rates[
        r0:r1, c0:c1
    ]
    return square
