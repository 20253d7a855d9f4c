"""Robust averaging of measurements in the fitted basis: MAD rejection, standard errors, covariance.

A measurement is a coefficient vector (the fit of one map, in the fitter's basis) and, optionally,
its map on the same aperture. :func:`robust_average` rejects the measurements whose coefficients
lie far from the others by a median-absolute-deviation rule, averages the rest and says how well
the average is known:

* for each coefficient ``j``, the median ``med_j`` and the scaled MAD
  ``s_j = 1.4826 median_k |c_kj - med_j|`` over the ``K`` measurements (1.4826 makes the MAD the
  standard deviation of a normal distribution);
* each measurement's distance from the median, ``r_k = sqrt(mean_j ((c_kj - med_j) / s_j)^2)``;
* its score, how far that distance lies out among the others' by the same rule,
  ``(r_k - median(r)) / (1.4826 MAD(r))``; it is rejected when the score exceeds ``threshold``
  (default 5). One coefficient far off is enough to move ``r_k``: a vibration burst during a
  phase-shifting set throws the tilts and a ripple, a fringe-order jump throws many terms at once.
  The second level matters for few measurements: with ``K = 6`` a coefficient's MAD is often a
  third of its spread, which would make a clean measurement's largest ``|c - med| / s`` over 36 terms
  look like an outlier; it inflates every measurement's distance alike, and the rule judges the
  distances against each other;
* the average of the kept measurements, the standard error of each coefficient ``std_j / sqrt(n)``
  (``ddof = 1``), the covariance of the average (the sample covariance over ``n``) and, with maps,
  the per-pixel mean and standard error over the kept maps that measured that pixel.

With fewer than :data:`MIN_FOR_REJECTION` (5) measurements nothing is rejected: the median and the
MAD of three or four values cannot tell an outlier from the spread.

The scores come from the coefficients only: the basis is the compact, well-conditioned description
of a map, so the rule costs ``K x M`` numbers whatever the map size. Where a coefficient does not
vary at all (a removed piston), its MAD is zero; a floor of ``1e-9`` of the coefficients' largest
magnitude keeps such a coefficient from rejecting a measurement over rounding.

References
----------
.. [1] P. J. Rousseeuw and C. Croux, "Alternatives to the median absolute deviation",
   J. Am. Stat. Assoc. 88, 1273-1283 (1993) (the MAD and its 1.4826 consistency factor).
.. [2] F. R. Hampel, "The influence curve and its role in robust estimation", J. Am. Stat. Assoc.
   69, 383-393 (1974) (rejection at a multiple of the MAD).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["DEFAULT_THRESHOLD", "MAD_SCALE", "RobustAverage", "TooFewMeasurements", "mad_scores", "robust_average"]

#: The MAD times this is the standard deviation of a normal distribution (1 / Phi^-1(3/4)).
MAD_SCALE = 1.4826
#: Rejection threshold in scaled MADs of the measurements' distances (module notes).
DEFAULT_THRESHOLD = 5.0
#: Fewest measurements the rule judges: the MAD of fewer is too unstable to reject on (they are averaged whole).
MIN_FOR_REJECTION = 5
_MAD_FLOOR = 1e-9  # of the largest coefficient magnitude (module notes)


class TooFewMeasurements(ValueError):
    """Fewer measurements than an average with a standard error needs, before or after rejection."""


@dataclass(frozen=True, eq=False)
class RobustAverage:
    """The robust average of K measurements on one aperture.

    Attributes
    ----------
    coefficients : ndarray, shape (M,)
        Mean of the kept coefficient vectors, in their units and basis.
    coefficient_stderr : ndarray, shape (M,)
        Standard error of each mean coefficient, ``std (ddof=1) / sqrt(n)``.
    coefficient_covariance : ndarray, shape (M, M)
        Covariance of the mean coefficients (sample covariance over ``n``); its diagonal is
        ``coefficient_stderr ** 2``.
    map : ndarray of float64, shape (H, W), or None
        Mean of the kept maps per pixel (NaN where none of them measured it); None without maps.
    map_stderr : ndarray of float64, shape (H, W), or None
        Standard error of ``map`` per pixel (NaN where fewer than two kept maps measured it).
    kept : tuple of int
        Indices (into the input) of the measurements averaged.
    rejected : tuple of int
        Indices of the measurements rejected.
    scores : ndarray, shape (K,)
        Each measurement's score (module notes): how many scaled MADs its distance from the median
        lies beyond the measurements' median distance.
    threshold : float
        The score above which a measurement was rejected.
    """

    coefficients: NDArray[np.float64]
    coefficient_stderr: NDArray[np.float64]
    coefficient_covariance: NDArray[np.float64]
    map: NDArray[np.float64] | None
    map_stderr: NDArray[np.float64] | None
    kept: tuple[int, ...]
    rejected: tuple[int, ...]
    scores: NDArray[np.float64]
    threshold: float

    @property
    def count(self) -> int:
        """Measurements averaged (``len(kept)``)."""
        return len(self.kept)

    def summary(self) -> dict[str, object]:
        """JSON-ready counts: kept, rejected (with their indices) and the threshold."""
        return {"kept": self.count, "rejected": len(self.rejected), "rejected_indices": list(self.rejected),
                "threshold_mad": self.threshold}


def robust_average(
    coefficients: NDArray[np.floating],
    maps: NDArray[np.floating] | None = None,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    min_kept: int = 3,
) -> RobustAverage:
    """Average measurements after rejecting those far from the rest by a MAD rule on their coefficients.

    Parameters
    ----------
    coefficients : array_like, shape (K, M)
        One coefficient vector per measurement, all in one basis (module notes).
    maps : array_like, shape (K, H, W), optional
        The measurements' maps on one aperture, NaN where a map has no value.
    threshold : float
        Rejection threshold in scaled MADs (``> 0``).
    min_kept : int
        Fewest measurements an average may keep (``>= 2``: a standard error needs two).

    Returns
    -------
    RobustAverage

    Raises
    ------
    ValueError
        If the arrays' shapes disagree, a coefficient is not finite, or an argument is out of range.
    TooFewMeasurements
        If fewer than ``min_kept`` measurements are given, or remain after rejection.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> c = np.array([0.0, 1.0, -2.0]) + 0.01 * rng.standard_normal((12, 3))
    >>> c[4] += [0.0, 3.0, 0.0]  # one measurement thrown off
    >>> average = robust_average(c)
    >>> average.rejected, bool(np.all(np.abs(average.coefficients - [0, 1, -2]) < 4 * average.coefficient_stderr))
    ((4,), True)
    """
    values = _checked_coefficients(coefficients)
    count = values.shape[0]
    threshold = _positive(threshold, "threshold")
    if isinstance(min_kept, bool) or not isinstance(min_kept, (int, np.integer)) or min_kept < 2:
        raise ValueError(f"min_kept: expected an integer >= 2, got {min_kept!r}")
    if count < min_kept:
        raise TooFewMeasurements(f"coefficients: {count} measurements, at least {min_kept} needed")
    scores = mad_scores(values)
    keep = scores <= threshold if count >= MIN_FOR_REJECTION else np.ones(count, dtype=bool)
    kept = tuple(int(k) for k in np.flatnonzero(keep))
    if len(kept) < min_kept:
        raise TooFewMeasurements(
            f"coefficients: {count - len(kept)} of {count} measurements rejected at {threshold:g} MAD, "
            f"{len(kept)} left, at least {min_kept} needed"
        )
    good = values[keep]
    mean = good.mean(axis=0)
    covariance = np.atleast_2d(np.cov(good, rowvar=False, ddof=1)) / len(kept)
    mean_map = stderr_map = None
    if maps is not None:
        mean_map, stderr_map = _map_statistics(_checked_maps(maps, count)[keep])
    return RobustAverage(
        coefficients=mean, coefficient_stderr=np.sqrt(np.diag(covariance)), coefficient_covariance=covariance,
        map=mean_map, map_stderr=stderr_map, kept=kept,
        rejected=tuple(int(k) for k in np.flatnonzero(~keep)), scores=scores, threshold=threshold,
    )


def mad_scores(coefficients: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each row's score (module notes): its MAD-scaled distance from the median, against the other rows', shape (K,)."""
    median = np.median(coefficients, axis=0)
    deviation = np.abs(coefficients - median)
    floor = _MAD_FLOOR * max(float(np.max(np.abs(coefficients))), np.finfo(np.float64).tiny)
    scale = np.maximum(MAD_SCALE * np.median(deviation, axis=0), floor)
    distance = np.sqrt(np.mean((deviation / scale) ** 2, axis=1))
    centre = np.median(distance)
    spread = max(MAD_SCALE * float(np.median(np.abs(distance - centre))), _MAD_FLOOR * max(float(centre), 1.0))
    return (distance - centre) / spread


def _map_statistics(maps: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-pixel mean and standard error over the maps that have a value there."""
    measured = np.isfinite(maps)
    counts = measured.sum(axis=0)
    filled = np.where(measured, maps, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = filled.sum(axis=0) / counts
        squares = np.where(measured, (maps - mean) ** 2, 0.0).sum(axis=0)
        stderr = np.sqrt(squares / (counts - 1) / counts)
    mean[counts == 0] = np.nan
    stderr[counts < 2] = np.nan
    return mean, stderr


def _checked_coefficients(coefficients: NDArray[np.floating]) -> NDArray[np.float64]:
    values = np.asarray(coefficients, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] < 1:
        raise ValueError(f"coefficients: expected shape (K, M), got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError("coefficients: expected finite values, got NaN or infinity")
    return values


def _checked_maps(maps: NDArray[np.floating], count: int) -> NDArray[np.float64]:
    values = np.asarray(maps, dtype=np.float64)
    if values.ndim != 3 or values.shape[0] != count:
        raise ValueError(f"maps: expected shape ({count}, H, W), one map per coefficient vector, got {values.shape}")
    return values


def _positive(value: float, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name}: expected a positive number, got {value!r}")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a positive finite number, got {value!r}")
    return float(value)
