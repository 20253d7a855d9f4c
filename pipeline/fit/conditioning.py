"""How well a basis is sampled: condition number and noise gain of its Gram matrix."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# Noise gain up to which a basis counts as well conditioned on an aperture: the level at which
# single coefficients stop meaning much (0.01 wave of pixel noise becomes ~1 wave of coefficient
# scatter at N/M ~ 1e4). Used by the ``auto`` method and by the mode counts a failure suggests.
WELL_CONDITIONED_NOISE_GAIN = 100.0


def normalised_gram(basis_gram: NDArray[np.float64], n_samples: int) -> NDArray[np.float64]:
    """The Gram matrix ``G = H^T H / N`` of a basis on N samples.

    For a basis with unit RMS over the aperture and perfectly uniform sampling, ``G`` is the
    identity; off-diagonal entries measure modal crosstalk.

    Parameters
    ----------
    basis_gram : ndarray, shape (M, M)
        ``H^T H`` of the unit-RMS basis on the samples.
    n_samples : int
        N, the number of samples.
    """
    return basis_gram / float(n_samples)


def gram_condition(gram: NDArray[np.float64]) -> float:
    """Condition number kappa(G) = lambda_max / lambda_min of a symmetric Gram matrix.

    This is the figure of Table 1 of the seed paper (Yang et al., "CSF-guided progressive
    quasi-conformal mapping", section 3.2.2). It is invariant to a common scale of ``G`` but not
    to the normalisation of individual modes; wavestack always reports it for unit-RMS modes.

    Parameters
    ----------
    gram : ndarray, shape (M, M)

    Returns
    -------
    float
        ``inf`` if the matrix is singular to working precision.
    """
    eigenvalues = np.linalg.eigvalsh(gram)
    smallest, largest = float(eigenvalues[0]), float(eigenvalues[-1])
    if smallest <= largest * np.finfo(np.float64).eps:
        return float("inf")
    return largest / smallest


def noise_gain(gram: NDArray[np.float64]) -> float:
    """Coefficient noise amplification relative to a basis orthonormal on the samples.

    With white noise of standard deviation sigma on N samples, least-squares coefficients have
    covariance ``sigma^2 (H^T H)^{-1} = (sigma^2 / N) G^{-1}``; a basis orthonormal (unit RMS) on
    the samples gives ``(sigma^2 / N) I``. The gain is the ratio of the RMS coefficient errors:
    ``sqrt(trace(G^{-1}) / M)``; it is 1 for an orthonormal basis and grows with crosstalk.

    Parameters
    ----------
    gram : ndarray, shape (M, M)
        The normalised Gram matrix ``H^T H / N`` of unit-RMS modes.

    Returns
    -------
    float
    """
    eigenvalues = np.linalg.eigvalsh(gram)
    if eigenvalues[0] <= 0:
        return float("inf")
    return float(np.sqrt(np.mean(1.0 / eigenvalues)))
