"""The figures of a fitted map: spike clipping and PV (PVr: :class:`~wavestack.pipeline.surface.RobustPVAnalyzer`).

* **Spike clipping**, as interferometer software offers it: pixels whose fit residual exceeds
  ``clip_sigma`` times the residual RMS are left out (marked :data:`~.quality.CLIPPED`) and the fit
  repeated. One cut is not enough: a few large spikes inflate the RMS they are judged by. So the
  cut is iterated on the residual (the limit from the RMS of the pixels still kept, until no more
  exceed it: a compiled walk per round) and the fit repeated once, for the whole set, as a
  downdate of the first fit (:meth:`Fitter.refit_without <wavestack.pipeline.fit.Fitter.refit_without>`:
  the clipped samples' rows taken out of its normal equations, the full refit's numbers to
  rounding, no pass over the map or the operator). The refit moves the residual by a hair
  (leaving ~60 of 140,000 pixels out moves the coefficients by 2e-5 waves RMS on the default
  station), so a pixel or two the refit leaves just past its own, slightly smaller limit stay:
  the residual PV stays within ~2 ``clip_sigma`` RMS, and a second round would chase a hair.
  With no spike the cut is one compiled pass over the residual and nothing is refitted.
* **PV** of the map less the physical terms the fit removed (piston and tilt, or power too), over
  the pixels used: what an optician reads as the map's peak to valley.
* **PVr** (Evans' robust PV) is the surface topic's :class:`~wavestack.pipeline.surface.RobustPVAnalyzer`,
  built once per adopted aperture on the pixels its fitter was built on, with the same physical
  terms removed, and measured on the pixels each set used (:func:`robust_pv`).

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

from ..fit import FitResult, Fitter, IllConditionedBasis, InvalidFrame
from ..fit import PhysicalTerms
from ..surface import RobustPVAnalyzer, measured_area
from .quality import CLIPPED

__all__ = ["MapStatistics", "clip_spikes", "map_pv", "pvr_analyzer", "robust_pv"]

#: Residuals below this are rounding, never a spike (map units: waves here, 0.6 pm at 633 nm).
SPIKE_FLOOR: Final = 1e-6


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
                sigma: float, *, residual: bool = False) -> tuple[FitResult, int]:
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
    residual : bool
        Give the refit's residual map too (one pass over the fitter's operator); its residual RMS
        and peak-to-valley are given either way.

    Returns
    -------
    (FitResult, int)
        The refit (:meth:`Fitter.refit_without <wavestack.pipeline.fit.Fitter.refit_without>`), or
        ``fit`` when nothing was clipped, and the pixels clipped.

    Raises
    ------
    InvalidFrame
        If clipping leaves too few samples to fit.
    """
    assert fit.residual_map is not None
    squares = fit.residual_rms ** 2 * fit.valid_count  # the residual map's own sum (a fit with its map)
    clipped = _clip(fit.residual_map, squares, fit.valid_count, sigma, SPIKE_FLOOR, flags)
    if clipped:
        spikes = (flags & CLIPPED) != 0
        fit = fitter.refit_without(waves, fit, spikes, residual=residual)
        waves[spikes] = np.nan
    return fit, clipped


def pvr_analyzer(fitted: NDArray[np.bool_], remove: str | None, dtype: str) -> RobustPVAnalyzer | None:
    """Evans' PVr on the pixels a fitter was built on (None where the 36 terms cannot be fitted there)."""
    try:
        return RobustPVAnalyzer(measured_area(fitted), remove=remove, dtype=np.dtype(dtype))
    except (IllConditionedBasis, ValueError):
        return None


def robust_pv(analyzer: RobustPVAnalyzer | None, waves: NDArray[np.float64]) -> float:
    """Evans' PVr of a map over its finite pixels; NaN without an analyzer or enough samples.

    Example
    -------
    >>> rows, cols = np.mgrid[:64, :64]
    >>> rho2 = ((rows - 31.5) ** 2 + (cols - 31.5) ** 2) / 30.0**2
    >>> waves = np.where(rho2 < 1, 0.1 * rho2, np.nan)  # a paraboloid: 0.1 waves PV, no residual
    >>> round(robust_pv(pvr_analyzer(rho2 < 1, "ptt", "float64"), waves), 3)
    0.099
    """
    if analyzer is None:
        return math.nan
    try:
        return analyzer.measure(waves, nan_policy="omit").pvr
    except InvalidFrame:
        return math.nan


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
def _clip(residual, squares, kept, sigma, floor, flags):  # type: ignore[no-untyped-def]
    """Cut ``|residual| > max(sigma * rms, floor)``, the RMS over the pixels still kept (``squares`` and
    ``kept`` at first: the fit's), until no more exceed; the clipped flag on each pixel cut. Returns
    how many were cut.

    The first round walks the map and holds the pixels above half its limit; later rounds, whose
    limits only fall, walk those alone while their limit stays above that half (else the map again).
    """
    flat = residual.ravel()
    marks = flags.ravel()
    held = np.empty(0, dtype=np.intp)
    held_above = np.inf  # every kept pixel with |residual| above this is in ``held``
    count = 0
    while kept > 0:
        limit = max(sigma * math.sqrt(max(squares, 0.0) / kept), floor)
        found = 0
        if limit > held_above:
            for i in held:
                value = flat[i]
                if abs(value) > limit and not marks[i] & 8:
                    marks[i] |= 8
                    squares -= value * value
                    kept -= 1
                    found += 1
        else:
            held_above = 0.5 * limit
            held = np.empty(flat.size, dtype=np.intp)
            n_held = 0
            for i in range(flat.size):
                value = flat[i]
                if value == value and abs(value) > held_above and not marks[i] & 8:
                    if abs(value) > limit:
                        marks[i] |= 8
                        squares -= value * value
                        kept -= 1
                        found += 1
                    else:
                        held[n_held] = i
                        n_held += 1
            held = held[:n_held]
        if found == 0:
            break
        count += found
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
