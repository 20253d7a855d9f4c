"""The figures of a fitted map: spike clipping, PV, and Evans' robust PV (PVr).

* **Spike clipping**, as interferometer software offers it: pixels whose fit residual exceeds
  ``clip_sigma`` times the residual RMS are left out (marked :data:`~.quality.CLIPPED`) and the fit
  repeated, until no pixel exceeds the limit of the new fit or :data:`MAX_CLIP_PASSES` passes have
  run. A single pass is not enough: a few large spikes inflate the RMS they are judged by, and the
  refit's RMS is smaller. With no spike the check is one compiled pass over the residual.
* **PV** of the map less the physical terms the fit removed (piston and tilt, or power too), over
  the pixels used: what an optician reads as the map's peak to valley.
* **PVr** (C. Evans, "PVr - a robust amplitude parameter for optical surface specification", Opt.
  Eng. 48(4) 043605, 2009): the PV of the 36-term Fringe Zernike fit of the map plus three times
  the RMS of that fit's residual. The fit is on the pixels used, with the same physical terms
  removed, by the ``qr`` method (the Fringe terms orthonormalised on the pixels: the same fitted
  surface as the plain circle polynomials, and stable on any aperture); its PV is taken over the
  pixels used. The fitted surface is smooth, so a spike or a wrong fringe order moves PVr by its
  share of the RMS only, where it moves PV by its full height.

The figures are shared with a Shack-Hartmann processor (:class:`MapStatistics`), which gives its
own reconstruction's values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numba
import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from ..fit import FitResult, Fitter, IllConditionedBasis, InvalidFrame, build_fitter
from ..fit import PhysicalTerms

__all__ = ["MAX_CLIP_PASSES", "PVR_MODES", "MapStatistics", "clip_spikes", "map_pv", "pvr_fitter", "robust_pv"]

#: Most fits spike clipping runs after the first (module notes).
MAX_CLIP_PASSES: Final = 3
#: Residuals below this are rounding, never a spike (map units: waves here, 0.6 pm at 633 nm).
SPIKE_FLOOR: Final = 1e-6
#: Evans' PVr fits the first 36 Fringe Zernike terms.
PVR_MODES: Final = 36


@dataclass(frozen=True)
class MapStatistics:
    """Figures of one result over the samples used, waves.

    Attributes
    ----------
    residual_rms, residual_pv : float
        RMS and peak-to-valley of the fit residual.
    pv : float
        Peak-to-valley of the map less the removed physical terms.
    pvr : float
        Evans' robust PV (module notes); NaN where no 36-term Fringe fit can be made.
    """

    residual_rms: float
    residual_pv: float
    pv: float
    pvr: float

    @classmethod
    def none(cls) -> MapStatistics:
        nan = float("nan")
        return cls(nan, nan, nan, nan)


def clip_spikes(fitter: Fitter, waves: NDArray[np.float64], flags: NDArray[np.uint8], fit: FitResult,
                sigma: float) -> tuple[FitResult, int]:
    """Leave out the residual's spikes and refit (module notes); ``waves`` and ``flags`` are updated in place.

    Parameters
    ----------
    fitter : Fitter
    waves : ndarray, shape (rows, cols)
        The map that was fitted (NaN where not used); clipped pixels become NaN.
    flags : ndarray of uint8, shape (rows, cols)
        The quality flags; clipped pixels get :data:`~.quality.CLIPPED`.
    fit : FitResult
        ``fitter``'s fit of ``waves`` with its residual map.
    sigma : float
        The limit, in residual RMS (> 0); never below :data:`SPIKE_FLOOR`.

    Returns
    -------
    (FitResult, int)
        The last fit (with its residual map) and the pixels clipped.

    Raises
    ------
    InvalidFrame
        If clipping leaves too few samples to fit.
    """
    clipped = 0
    for _ in range(MAX_CLIP_PASSES):
        assert fit.residual_map is not None
        found = _clip(fit.residual_map, max(sigma * fit.residual_rms, SPIKE_FLOOR), waves, flags)
        if not found:
            break
        clipped += found
        fit = fitter.fit(waves, nan_policy="omit", residual=True)
    return fit, clipped


def pvr_fitter(aperture: Aperture, fit_mask: NDArray[np.bool_], remove: str | None, dtype: str) -> Fitter | None:
    """The 36-term Fringe fitter of PVr on the pixels a fit uses (None where the terms cannot be fitted)."""
    try:
        return build_fitter(aperture, method="qr", modes=PVR_MODES, ordering="fringe", remove=remove,
                            fit_mask=fit_mask, dtype=np.dtype(dtype))
    except (IllConditionedBasis, ValueError):
        return None


def robust_pv(fitter: Fitter | None, waves: NDArray[np.float64]) -> float:
    """Evans' PVr of a map over its finite pixels (module notes); NaN without a fitter or samples.

    Example
    -------
    >>> rows, cols = np.mgrid[:64, :64]
    >>> rho2 = ((rows - 31.5) ** 2 + (cols - 31.5) ** 2) / 30.0**2
    >>> disk = Aperture.from_mask(rho2 < 1)
    >>> waves = np.where(rho2 < 1, 0.1 * rho2, np.nan)  # a paraboloid: 0.1 waves PV, no residual
    >>> round(robust_pv(pvr_fitter(disk, disk.mask, "ptt", "float64"), waves), 3)
    0.099
    """
    if fitter is None:
        return math.nan
    try:
        fit = fitter.fit(waves, nan_policy="omit")
    except InvalidFrame:
        return math.nan
    low, high = _extremes_where_finite(fitter.surface(fit.coefficients), waves)
    return high - low + 3.0 * fit.residual_rms


def map_pv(waves: NDArray[np.float64], removed: PhysicalTerms | None) -> float:
    """Peak-to-valley of a map less the removed physical terms, over its finite pixels (NaN: none)."""
    if removed is None:
        low, high = _extremes_where_finite(waves, waves)
        return high - low
    power = 0.0 if removed.power is None else removed.power
    low, high = _extremes_less_terms(waves, removed.centre[0], removed.centre[1], removed.radius_px, removed.piston,
                                     removed.tilt_x, removed.tilt_y, power)
    return high - low


@numba.njit(nogil=True, cache=True)
def _clip(residual, limit, waves, flags):  # type: ignore[no-untyped-def]
    """NaN into ``waves`` and the clipped flag wherever ``|residual| > limit``; returns how many."""
    rows, cols = residual.shape
    count = 0
    for r in range(rows):
        for c in range(cols):
            value = residual[r, c]
            if value == value and abs(value) > limit:
                waves[r, c] = np.nan
                flags[r, c] |= 8
                count += 1
    return count


@numba.njit(nogil=True, cache=True)
def _extremes_where_finite(values, reference):  # type: ignore[no-untyped-def]
    """(min, max) of ``values`` where ``reference`` is finite (NaN, NaN when nowhere)."""
    low, high = np.inf, -np.inf
    rows, cols = values.shape
    for r in range(rows):
        for c in range(cols):
            if reference[r, c] == reference[r, c]:
                v = values[r, c]
                low = min(low, v)
                high = max(high, v)
    if low > high:
        return np.nan, np.nan
    return low, high


@numba.njit(nogil=True, cache=True)
def _extremes_less_terms(waves, cx, cy, radius, piston, tilt_x, tilt_y, power):  # type: ignore[no-untyped-def]
    """(min, max) of ``waves - (piston + tilt_x x + tilt_y y + power (x^2 + y^2))``, x = (col - cx) / R, y up."""
    low, high = np.inf, -np.inf
    rows, cols = waves.shape
    for r in range(rows):
        y = (cy - r) / radius
        for c in range(cols):
            w = waves[r, c]
            if w == w:
                x = (c - cx) / radius
                v = w - (piston + tilt_x * x + tilt_y * y + power * (x * x + y * y))
                low = min(low, v)
                high = max(high, v)
    if low > high:
        return np.nan, np.nan
    return low, high
