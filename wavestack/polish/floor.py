"""The floor of a run: the figure the best job within the limits leaves, plus what the real machine adds.

A job's outcome, measured, is the predicted residual (the surface less the host's predicted
removal: what the tool cannot reach within the machine's limits, the first term) spoilt by the
real machine's departures from the host's model and by noise. The terms are independent, so
their RMS adds in quadrature (the same budget the convergence tests check the simulated machine
against):

- ``reach_nm``: the predicted residual RMS of the job (the executed program, host TIF);
- ``model_nm``: the tool's rate and width uncertainty (``tif_rate_uncertainty``,
  ``tif_width_uncertainty``): the executed dwell deposited with a tool ``1 +- w`` as wide and
  ``1 +- r`` as fast, less the host's removal, PTT removed, RMS over the aperture; the largest of
  the four sign combinations (the host knows the size of its model error, not its sign). For a
  measured TIF map the width term is left out (its shape is measured) and the rate term kept;
- ``efficiency_nm``: a per-point efficiency uniform on ``1 +- s`` gives a removal error of
  variance ``s^2 / 3 * sum_k (d_k K(x - x_k))^2``: each program point's squared dwell at its
  nearest pixel, convolved with ``K^2`` (per point, not per pixel of the executed dwell map: that
  map shares a point between pixels, which would understate the variance up to 4x);
- ``process_nm``: the machine's process noise;
- the measurement's noise, twice (the measurement before and the one after).

``floor_nm`` is what the next measurement should show if the job is run; the loop stops in
``floor-reached`` when the measured RMS is within ``floor_tolerance`` of it: no job within the
machine's limits and its model errors would lower the figure by more than that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import fftconvolve

from wavestack.pipeline import remove_physical_terms
from wavestack.pipeline.polishing import ToolInfluence, removal_nm
from wavestack.polish.measurement import surface_stats

__all__ = ["JobFloor", "job_floor"]


@dataclass(frozen=True)
class JobFloor:
    """The floor of one job, nm RMS over the clear aperture (module notes).

    Example
    -------
    >>> JobFloor(3.0, 4.0, 0.0, 0.0, 0.0).floor_nm
    5.0
    """

    reach_nm: float
    model_nm: float
    efficiency_nm: float
    process_nm: float
    measurement_nm: float

    @property
    def floor_nm(self) -> float:
        """All the terms in quadrature."""
        return math.sqrt(self.reach_nm**2 + self.model_nm**2 + self.efficiency_nm**2 + self.process_nm**2
                         + 2.0 * self.measurement_nm**2)

    def describe(self) -> str:
        return (f"floor {self.floor_nm:.2f} nm (reach {self.reach_nm:.2f}, tool model {self.model_nm:.2f}, "
                f"efficiency {self.efficiency_nm:.2f}, process {self.process_nm:.2f}, "
                f"measurement {self.measurement_nm:.2f} x 2)")


def job_floor(dwell_s: NDArray[np.float64], predicted_rms_nm: float, mask: NDArray[np.bool_], tif: ToolInfluence, *,
              points_px: NDArray[np.float64], points_dwell_s: NDArray[np.float64], rate_uncertainty: float,
              width_uncertainty: float, efficiency_spread: float, process_noise_nm: float,
              measurement_noise_nm: float) -> JobFloor:
    """The floor of a job whose executed dwell map is ``dwell_s`` (s per pixel, the grid of ``mask``).

    Parameters
    ----------
    dwell_s : ndarray (H, W)
        The program's executed dwell map.
    predicted_rms_nm : float
        The job's predicted residual RMS (host TIF), nm.
    mask : ndarray of bool (H, W)
        The clear aperture.
    tif : ToolInfluence
        The host's model.
    points_px : ndarray (K, 2)
        The program's points, (row, col) pixels (fractional).
    points_dwell_s : ndarray (K,)
        Their dwell, s.
    rate_uncertainty, width_uncertainty, efficiency_spread : float
        Fractions (``[polishing]``).
    process_noise_nm, measurement_noise_nm : float
        nm RMS.

    Returns
    -------
    JobFloor
    """
    host = removal_nm(dwell_s, tif)
    model = 0.0
    for rate in (1.0 - rate_uncertainty, 1.0 + rate_uncertainty):
        for width in ((1.0 - width_uncertainty, 1.0 + width_uncertainty) if tif.kind == "gaussian" else (1.0,)):
            other = _scaled(tif, rate, width)
            departure, _ = surface_stats(remove_physical_terms(removal_nm(dwell_s, other) - host, mask, "ptt")[0], mask)
            model = max(model, departure)
    at = np.zeros(dwell_s.shape)
    rows = np.clip(np.rint(points_px[:, 0]).astype(np.intp), 0, dwell_s.shape[0] - 1)
    cols = np.clip(np.rint(points_px[:, 1]).astype(np.intp), 0, dwell_s.shape[1] - 1)
    np.add.at(at, (rows, cols), np.asarray(points_dwell_s, dtype=np.float64) ** 2)
    squared = fftconvolve(at, tif.kernel_nm_per_s**2, mode="same")
    efficiency = math.sqrt(max(float(np.mean(squared[mask])), 0.0) * efficiency_spread**2 / 3.0)
    return JobFloor(float(predicted_rms_nm), model, efficiency, float(process_noise_nm), float(measurement_noise_nm))


def _scaled(tif: ToolInfluence, rate: float, width: float) -> ToolInfluence:
    """The tool ``rate`` times as fast and (a Gaussian) ``width`` times as wide."""
    if tif.kind == "gaussian" and tif.fwhm_mm is not None:
        return ToolInfluence.gaussian(tif.fwhm_mm * width, tif.peak_rate_nm_s * rate, tif.pixel_mm,
                                      truncate_sigma=tif.truncate_sigma)
    return ToolInfluence.from_map(tif.kernel_nm_per_s * rate, tif.pixel_mm)
