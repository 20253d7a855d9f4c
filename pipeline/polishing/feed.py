"""From requested dwell to the feed the machine can run: the feed floor and the acceleration bound.

The tool moves continuously; the move into point k (of length ``s_k`` mm, one lattice step on a
raster) takes ``dwell_k`` s, so its feed is ``v_k = s_k / dwell_k`` (``step_mm / dwell_k`` on a
raster). Two limits shape the feed:

* the machine cannot move faster than ``max_feed``, so ``dwell_k >= s_k / max_feed``: shorter
  dwells (zero included, for points the tool only crosses) are raised to that floor;
* the path speed changes by at most ``max_accel``: ``v_k^2 <= v_{k-1}^2 + 2 a s_k`` and
  ``v_{k-1}^2 <= v_k^2 + 2 a s_k``, the program starting from rest (``v_0^2 <= 2 a s_0``) and
  ending at rest within one step (``v_{K-1}^2 <= 2 a step``). A forward pass, then a backward
  pass, lowers the feeds to the largest ones that obey this (the usual time-optimal velocity
  profile of CNC planners, e.g. Altintas, Manufacturing Automation, 2nd ed., ch. 6), which only
  raises dwell.

The bound is on path speed: a raster turn (a 90 degree corner) is taken as the machine's own
corner blending takes it, as in published dwell schedulers that bound the feed and the
acceleration along the path.

Both passes plan to the limits shrunk by :data:`PLAN_MARGIN` (a relative 1e-9), so that
rounding never lets a planned program fail :func:`~.program_checks.check_program`, which uses
the limits as they are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

PLAN_MARGIN = 1e-9
"""Relative amount by which the planner stays inside the feed and acceleration limits."""

_COUNT_RTOL = 1e-6  # a dwell raised by less than this fraction is not counted as raised


@dataclass(frozen=True)
class FeedProfile:
    """The dwell and feed the machine runs, and what the limits added.

    Attributes
    ----------
    dwell_s, feed_mm_s : ndarray of float64, shape (K,)
        Executed dwell at each point, s, and feed on the move into it, mm/s
        (``dwell_s * feed_mm_s == segment length``).
    floor_extra_s : float
        Dwell added by the feed floor ``s_k / max_feed``, s (summed over points).
    accel_extra_s : float
        Dwell added on top by the acceleration bound, s.
    floor_points, accel_points : int
        Points whose dwell the floor raised, and points the acceleration bound raised further.
    """

    dwell_s: NDArray[np.float64]
    feed_mm_s: NDArray[np.float64]
    floor_extra_s: float
    accel_extra_s: float
    floor_points: int
    accel_points: int


def segment_lengths_mm(x_mm: NDArray[np.float64], y_mm: NDArray[np.float64], step_mm: float) -> NDArray[np.float64]:
    """Length of the move into each point, mm: ``step_mm`` for the first (its approach), then the distances.

    Parameters
    ----------
    x_mm, y_mm : ndarray, shape (K,)
    step_mm : float

    Returns
    -------
    ndarray of float64, shape (K,)
    """
    lengths = np.empty(np.shape(x_mm), dtype=np.float64)
    if lengths.size:
        lengths[0] = step_mm
        lengths[1:] = np.hypot(np.diff(x_mm), np.diff(y_mm))
    return lengths


def feed_profile(
    requested_s: NDArray[np.float64],
    segment_mm: NDArray[np.float64],
    step_mm: float,
    max_feed_mm_s: float,
    max_accel_mm_s2: float,
) -> FeedProfile:
    """Feeds and dwells that honour the requested dwell, the feed limit and the acceleration limit.

    Parameters
    ----------
    requested_s : ndarray, shape (K,)
        Requested dwell per point, s, >= 0 (0 for points only crossed).
    segment_mm : ndarray, shape (K,)
        Length of the move into each point, mm, > 0 (:func:`segment_lengths_mm`).
    step_mm : float
        Lattice step, mm: the distance in which the program comes to rest after its last point.
    max_feed_mm_s, max_accel_mm_s2 : float
        Machine limits, mm/s and mm/s^2.

    Returns
    -------
    FeedProfile
        ``dwell_s >= requested_s`` everywhere; equal where the request is above the floor set
        by both limits.

    Examples
    --------
    >>> p = feed_profile(np.array([0.0, 1.0, 0.0]), np.ones(3), 1.0, 10.0, 1e6)
    >>> p.dwell_s.round(6).tolist(), p.floor_points
    ([0.1, 1.0, 0.1], 2)
    """
    feed_max = max_feed_mm_s * (1.0 - PLAN_MARGIN)
    accel2 = 2.0 * max_accel_mm_s2 * (1.0 - PLAN_MARGIN)
    with np.errstate(divide="ignore"):
        cap = np.where(requested_s > 0, np.minimum(segment_mm / requested_s, feed_max), feed_max)
    speed = _bounded_speeds(cap.tolist(), (accel2 * segment_mm).tolist(), accel2 * step_mm)
    # never an ulp short of the request (s / (s / d) may round below d); the feed follows the dwell
    dwell = np.maximum(segment_mm / speed, requested_s)
    feed = segment_mm / dwell
    floor = np.maximum(segment_mm / cap, requested_s)  # never an ulp below the request either
    return FeedProfile(
        dwell_s=dwell,
        feed_mm_s=feed,
        floor_extra_s=float(np.sum(floor - requested_s)),
        accel_extra_s=float(np.sum(dwell - floor)),
        floor_points=int(np.count_nonzero(floor > requested_s * (1.0 + _COUNT_RTOL))),
        accel_points=int(np.count_nonzero(dwell > floor * (1.0 + _COUNT_RTOL))),
    )


def _bounded_speeds(cap: list[float], gain: list[float], stop_gain: float) -> NDArray[np.float64]:
    """Forward-backward pass: speeds <= cap with |v_k^2 - v_{k-1}^2| <= gain[k], from and to rest."""
    speeds = [0.0] * len(cap)
    before = 0.0  # squared speed on the previous move: at rest before the first
    for k, (limit, g) in enumerate(zip(cap, gain)):
        speeds[k] = min(limit, math.sqrt(before + g))
        before = speeds[k] * speeds[k]
    after, after_gain = 0.0, stop_gain  # at rest one step after the last point
    for k in range(len(cap) - 1, -1, -1):
        speeds[k] = min(speeds[k], math.sqrt(after + after_gain))
        after, after_gain = speeds[k] * speeds[k], gain[k]
    return np.asarray(speeds, dtype=np.float64)
