"""The simulated machine's own tool influence function: a Gaussian footprint deposited on a pixel grid.

The machine knows its tool, not the host's model of it: a circular Gaussian removal-rate profile

    rate(r) = peak_rate_nm_s * exp(-r^2 / (2 sigma^2)),   sigma = fwhm_mm / (2 sqrt(2 ln 2)),

sampled at pixel centres (Preston's law: removal = rate x dwell; Jones, Appl. Opt. 16, 218, 1977).
A dwell ``t`` at ``(x_mm, y_mm)`` removes ``t * rate`` at every pixel within ``4 sigma`` of the
point (beyond, the profile is below ``exp(-8) = 3.4e-4`` of the peak and is left out; the volume
left out is below ``exp(-8)`` of the whole). The footprint is separable, so it is built as the
outer product of two 1-D profiles. Pixels off the grid (the tool partly over the part's edge)
remove nothing.

The machine frame (mm, origin at the grid centre, x right, y up) maps to pixels as
``col = x_mm / pixel_mm + (W - 1) / 2`` and ``row = (H - 1) / 2 - y_mm / pixel_mm``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["GaussianTool"]

_FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
_REACH_SIGMA = 4.0


@dataclass(frozen=True)
class GaussianTool:
    """A Gaussian tool on a pixel grid.

    Attributes
    ----------
    fwhm_mm
        Full width at half maximum of the removal profile, mm (> 0).
    peak_rate_nm_s
        Removal rate at the centre, nm/s (>= 0).
    pixel_mm
        Grid pixel size on the part, mm (> 0).

    Examples
    --------
    >>> tool = GaussianTool(fwhm_mm=1.0, peak_rate_nm_s=10.0, pixel_mm=0.1)
    >>> grid = np.zeros((41, 41))
    >>> tool.deposit(grid, 0.0, 0.0, 2.0)   # 2 s at the centre: 20 nm at the centre pixel
    >>> round(float(grid[20, 20]), 9), round(float(grid.sum() / tool.volume_per_second_px()), 3)  # 4-sigma cut
    (20.0, 2.0)
    """

    fwhm_mm: float
    peak_rate_nm_s: float
    pixel_mm: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fwhm_mm) and self.fwhm_mm > 0):
            raise ValueError(f"GaussianTool: fwhm_mm must be finite and > 0, got {self.fwhm_mm!r}")
        if not (math.isfinite(self.peak_rate_nm_s) and self.peak_rate_nm_s >= 0):
            raise ValueError(f"GaussianTool: peak_rate_nm_s must be finite and >= 0, got {self.peak_rate_nm_s!r}")
        if not (math.isfinite(self.pixel_mm) and self.pixel_mm > 0):
            raise ValueError(f"GaussianTool: pixel_mm must be finite and > 0, got {self.pixel_mm!r}")

    @property
    def sigma_px(self) -> float:
        """Standard deviation of the profile, pixels."""
        return self.fwhm_mm / _FWHM_PER_SIGMA / self.pixel_mm

    def volume_per_second_px(self) -> float:
        """Removal summed over pixels per second of dwell, nm px^2/s, for a footprint wholly on the grid.

        The continuous integral ``2 pi sigma^2 peak``; the pixel sum equals it to within 1e-6 for
        sigma >= 1 px (Poisson summation: the error falls as exp(-2 pi^2 sigma^2)).
        """
        return 2.0 * math.pi * self.sigma_px ** 2 * self.peak_rate_nm_s

    def deposit(self, grid: NDArray[np.float64], x_mm: float, y_mm: float, dwell_s: float) -> None:
        """Add the removal of ``dwell_s`` seconds at ``(x_mm, y_mm)`` into ``grid`` (H, W), nm, in place."""
        if dwell_s <= 0 or self.peak_rate_nm_s == 0:
            return
        height, width = grid.shape
        col = x_mm / self.pixel_mm + (width - 1) / 2.0
        row = (height - 1) / 2.0 - y_mm / self.pixel_mm
        sigma = self.sigma_px
        reach = int(math.ceil(_REACH_SIGMA * sigma))
        r0, r1 = max(0, int(math.floor(row)) - reach), min(height, int(math.floor(row)) + reach + 2)
        c0, c1 = max(0, int(math.floor(col)) - reach), min(width, int(math.floor(col)) + reach + 2)
        if r0 >= r1 or c0 >= c1:
            return
        rows = np.arange(r0, r1, dtype=np.float64) - row
        cols = np.arange(c0, c1, dtype=np.float64) - col
        profile_r = np.exp(-0.5 * (rows / sigma) ** 2)
        profile_c = np.exp(-0.5 * (cols / sigma) ** 2)
        grid[r0:r1, c0:c1] += (self.peak_rate_nm_s * dwell_s) * np.outer(profile_r, profile_c)
