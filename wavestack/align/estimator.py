"""The misalignment estimate: a truncated-SVD solve of the normalised sensitivity matrix.

``measured - nominal = A x`` with ``x`` the normalised state change (:mod:`.sensitivity`); the
pseudo-inverse keeps the singular values above ``rcond`` times the largest and drops the rest, as
Rubin's active optics does (a threshold rather than a count: with five columns of one scale a
relative threshold says which directions the field points cannot see). Damped least squares would
serve as well; the truncation was chosen because a dropped direction is then *not moved at all*
(damping still moves it a little, driven by noise). W is not a column (:mod:`.sensitivity`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline.telescope import Sensitivity

__all__ = ["Estimate", "estimate_state"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Estimate:
    """The estimated state and how it was solved.

    Attributes
    ----------
    state : ndarray (5,)
        X Y Z mm, U V deg: the linearisation point plus the solved change.
    kept : int
        Singular values kept.
    singular_values : ndarray (5,)
        Of the normalised matrix, largest first.
    residual_rms_waves : float
        RMS over rows of what the linear model leaves of ``measured - nominal``.
    """

    state: FloatArray
    kept: int
    singular_values: FloatArray
    residual_rms_waves: float


def estimate_state(sensitivity: Sensitivity, measured: NDArray[np.floating], *, rcond: float = 1e-3) -> Estimate:
    """Solve for the state from measured terms (module notes).

    Parameters
    ----------
    sensitivity : Sensitivity
    measured : ndarray (F * T,)
        The measured terms, stacked as the matrix's rows, waves.
    rcond : float
        Relative singular-value threshold, 0 < rcond < 1.

    Raises
    ------
    ValueError
        ``measured`` of the wrong length or not finite.

    Examples
    --------
    >>> from wavestack.pipeline.telescope import Sensitivity
    >>> s = Sensitivity(np.vstack([np.eye(5), np.eye(5)]), np.zeros(10), np.zeros(5), np.full(5, 0.1))
    >>> np.round(estimate_state(s, np.tile([1.0, 0, 0, 0, 2.0], 2)).state, 6).tolist()
    [0.1, 0.0, 0.0, 0.0, 0.2]
    """
    y = np.asarray(measured, dtype=np.float64)
    if y.shape != sensitivity.nominal.shape or not np.all(np.isfinite(y)):
        raise ValueError(f"measured: expected {sensitivity.nominal.shape[0]} finite terms, got shape {y.shape}")
    if not 0.0 < rcond < 1.0:
        raise ValueError(f"rcond: expected 0 < rcond < 1, got {rcond}")
    u, s, vt = np.linalg.svd(sensitivity.matrix, full_matrices=False)
    keep = s > rcond * s[0] if s.size and s[0] > 0 else np.zeros(s.shape, bool)
    rhs = u.T @ (y - sensitivity.nominal)
    x = vt.T @ np.where(keep, rhs / np.where(keep, s, 1.0), 0.0)
    residual = y - sensitivity.nominal - sensitivity.matrix @ x
    return Estimate(sensitivity.at + x * sensitivity.scales, int(keep.sum()), s,
                    float(np.sqrt(np.mean(residual ** 2))))
