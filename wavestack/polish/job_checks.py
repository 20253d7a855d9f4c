"""Job-level safety, checked on the host before a job leaves it (the machine checks again).

A job goes to the machine only when every rule holds; :func:`check_job` raises :class:`JobUnsafe`
naming the first that does not:

- the dwell map is finite and non-negative, and its total is at most ``max_total_dwell_s``;
- the deepest removal the program plans (TIF x executed dwell) is at most ``max_removal_nm``, and
  finite everywhere: one run never takes more than the configured depth off the part, whatever the
  solver asked for;
- the job's aperture is the measurement's, and the measurement's is the campaign's (a job
  computed for one aperture is never run on another);
- the measurement is fresh: its oldest map at most ``freshness_s`` old when the job is sent.

Feed, acceleration, per-point dwell and travel are the machine program's own check
(``check_program`` of the polishing pipeline), run before this one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.polish.measurement import ApertureKey, Measurement

__all__ = ["JobRules", "JobUnsafe", "check_job"]


class JobUnsafe(ValueError):
    """A job that must not be sent; the message names the rule, the value and the limit."""


@dataclass(frozen=True)
class JobRules:
    """The job-level limits (from ``[polishing]``).

    Attributes
    ----------
    max_removal_nm : float
        Deepest planned removal of one job, nm.
    max_total_dwell_s : float
    freshness_s : float
    """

    max_removal_nm: float
    max_total_dwell_s: float
    freshness_s: float


def check_job(rules: JobRules, *, dwell_s: NDArray[np.floating], removal_nm: NDArray[np.floating],
              job_aperture: ApertureKey, measurement: Measurement, campaign_aperture: ApertureKey,
              now_ns: int) -> None:
    """Raise :class:`JobUnsafe` unless every rule of the module notes holds (pure).

    Parameters
    ----------
    rules : JobRules
    dwell_s : ndarray (H, W)
        The dwell the machine will execute, s per grid point.
    removal_nm : ndarray (H, W)
        The removal it plans, nm.
    job_aperture : ApertureKey
        The aperture the job file carries.
    measurement : Measurement
        What the job was computed from.
    campaign_aperture : ApertureKey
    now_ns : int
        ``time.time_ns()`` as the job is sent.

    Example
    -------
    >>> mask = np.ones((4, 4), bool)
    >>> from wavestack.polish.measurement import average_surface
    >>> from wavestack.station import MapSample
    >>> m = average_surface([MapSample(np.zeros((4, 4)), True, None, 0, 0)] * 2, wavelength_nm=600.0,
    ...                     reflection_factor=2.0, min_count=2)
    >>> check_job(JobRules(10.0, 100.0, 5.0), dwell_s=np.ones((4, 4)), removal_nm=np.ones((4, 4)),
    ...           job_aperture=m.aperture, measurement=m, campaign_aperture=m.aperture, now_ns=10**9)
    """
    dwell = np.asarray(dwell_s, dtype=np.float64)
    if not np.all(np.isfinite(dwell)):
        raise JobUnsafe("dwell map: expected finite dwell times, got NaN or infinity")
    if dwell.min(initial=0.0) < 0:
        raise JobUnsafe(f"dwell map: expected dwell >= 0 s everywhere, got {dwell.min():.3g} s")
    total = float(dwell.sum())
    if not total <= rules.max_total_dwell_s:
        raise JobUnsafe(f"total dwell {total:.1f} s exceeds max_total_dwell_s = {rules.max_total_dwell_s:g} s")
    removal = np.asarray(removal_nm, dtype=np.float64)
    if not np.all(np.isfinite(removal)):
        raise JobUnsafe("planned removal: expected finite values, got NaN or infinity")
    deepest = float(removal.max(initial=0.0))
    if not deepest <= rules.max_removal_nm:
        raise JobUnsafe(f"planned removal {deepest:.1f} nm deep exceeds max_removal_nm_per_run = "
                        f"{rules.max_removal_nm:g} nm")
    if measurement.aperture != campaign_aperture:
        raise JobUnsafe(f"the measurement's aperture ({measurement.aperture.pixels} pixels, "
                        f"{measurement.aperture.digest}) is not the campaign's ({campaign_aperture.pixels} pixels, "
                        f"{campaign_aperture.digest})")
    if job_aperture != measurement.aperture:
        raise JobUnsafe(f"the job's aperture ({job_aperture.pixels} pixels, {job_aperture.digest}) is not the "
                        f"measured one ({measurement.aperture.pixels} pixels, {measurement.aperture.digest})")
    age = measurement.age_s(now_ns)
    if not age <= rules.freshness_s:
        raise JobUnsafe(f"the measurement is {age:.1f} s old; expected at most freshness_s = {rules.freshness_s:g} s")
