"""From the triangular factor of a basis to the maps between solved and reported coefficients.

Both refit paths solve for the coefficients of the orthonormalised columns ``Q = H R^-1``; these
M x M maps turn them into the method's own coefficients (in the output normalisation) and back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from .conditioning import gram_condition, noise_gain, normalised_gram
from .orthonormal import factor_quality


@dataclass(frozen=True)
class CoefficientMaps:
    """Coefficient maps and the basis quality figures of a build.

    Attributes
    ----------
    coefficient_transform : ndarray, shape (M, M)
        Solved -> reported coefficients.
    from_coefficients : ndarray, shape (M, M)
        Reported -> solved coefficients.
    circle_transform : ndarray, shape (M, M) or None
        ``qr`` only: solved -> circle-polynomial coefficients.
    kappa, gain : float
        kappa(G) and noise gain of the reported basis on the samples.
    """

    coefficient_transform: NDArray[np.float64]
    from_coefficients: NDArray[np.float64]
    circle_transform: NDArray[np.float64] | None
    kappa: float
    gain: float


def coefficient_maps(
    method: str, scale: NDArray[np.float64], triangular: NDArray[np.float64],
    gram: NDArray[np.float64], n_samples: int,
) -> CoefficientMaps:
    """The maps for ``method`` from R (``H = Q R``) and the Gram matrix of ``[Q | Q_E]``.

    Parameters
    ----------
    method : str
        ``qr`` reports the orthonormal coefficients themselves; every other method the basis'.
    scale : ndarray, shape (M,)
        Each mode's factor from unit RMS to the output normalisation.
    triangular : ndarray, shape (M, M)
    gram : ndarray, shape (M + k, M + k)
    n_samples : int
    """
    n_modes = len(scale)
    kappa, gain = factor_quality(triangular)
    to_basis = scale[:, None] * scipy.linalg.solve_triangular(
        triangular, np.eye(n_modes), lower=False
    )  # orthonormal coefficients -> the basis' own coefficients, in the output normalisation
    if method == "qr":
        own_gram = normalised_gram(gram[:n_modes, :n_modes], n_samples)
        return CoefficientMaps(np.eye(n_modes), np.eye(n_modes), to_basis,
                               gram_condition(own_gram), noise_gain(own_gram))
    return CoefficientMaps(to_basis, triangular / scale[None, :], None, kappa, gain)
