"""Averaging measurements in the fitted basis: robust rejection by a MAD rule on the coefficients, the
per-pixel and per-coefficient standard errors and the coefficients' covariance.

>>> from wavestack.pipeline.averaging import robust_average
"""

from __future__ import annotations

from .robust import DEFAULT_THRESHOLD, MAD_SCALE, RobustAverage, TooFewMeasurements, mad_scores, robust_average

__all__ = ["DEFAULT_THRESHOLD", "MAD_SCALE", "RobustAverage", "TooFewMeasurements", "mad_scores", "robust_average"]
