"""Orthonormalising a basis on its samples: CholeskyQR2 and what its factor says.

A fitter never solves ``H^T H c = H^T w`` with a Cholesky factor of ``G = H^T H``: that squares
the condition number. It stores ``Q`` from ``H = Q R`` instead (Q orthonormal on the samples)
and keeps ``R`` to convert coefficients, so errors grow with kappa(H) = sqrt(kappa(G)). Measured
on a 3.5:1 rectangle with 36 circle modes (kappa(G) = 3.4e10): the normal equations miss exact
0.02-wave coefficients by 3.7e-8, the orthonormal route by 3e-13
(``benchmarks/bench_numerics.py``).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from .conditioning import WELL_CONDITIONED_NOISE_GAIN
from .normal_equations import IllConditionedBasis

# Largest condition number of the Gram matrix G = H^T H / N that still gives meaningful
# coefficients: CholeskyQR2 is accurate for kappa(H) up to about eps**-0.5 (Fukaya et al. 2014),
# i.e. kappa(G) up to 1/eps = 2**52 = 4503599627370496 (exact in float64), and past it the
# coefficients' noise gain exceeds 1e7 anyway. This one number is compared and printed.
MAX_GRAM_CONDITION = 1.0 / float(np.finfo(np.float64).eps)
MAX_BASIS_CONDITION = float(np.sqrt(MAX_GRAM_CONDITION))  # kappa(H), the same limit (2**26)
# The suggested mode count keeps kappa(G) this much below the limit, so that a refit with
# those modes (a fresh factorisation, not the leading block of this one) passes for sure.
_ADVICE_MARGIN = 100.0


def distinct_figures(value: float, limit: float) -> tuple[str, str]:
    """``value`` and ``limit`` printed with the fewest significant digits (at least 3) that keep
    them as different as they are: a value above the limit never prints as equal or below it.

    Parameters
    ----------
    value, limit : float

    Returns
    -------
    (str, str)
    """
    for digits in range(3, 18):
        shown_value, shown_limit = f"{value:.{digits}g}", f"{limit:.{digits}g}"
        if (float(shown_value) > float(shown_limit)) == (value > limit) and (
            float(shown_value) < float(shown_limit)
        ) == (value < limit):
            return shown_value, shown_limit
    return repr(value), repr(limit)


def usable_mode_count(triangular: NDArray[np.float64], limit: float = MAX_GRAM_CONDITION) -> int:
    """The largest k whose first k modes are well conditioned on the samples.

    Well conditioned: noise gain at most ``WELL_CONDITIONED_NOISE_GAIN`` and kappa(G) at most
    ``limit / 100``. With ``H = Q R`` (R upper triangular), the first k columns are
    ``Q[:, :k] R[:k, :k]``, so their Gram matrix is ``R[:k, :k]^T R[:k, :k]``: its eigenvalues are
    the squared singular values of the leading block.

    Parameters
    ----------
    triangular : ndarray, shape (M, M)
        R of the full basis.
    limit : float
        The kappa(G) limit; the count keeps a hundredfold margin below it.

    Returns
    -------
    int
        0 if not even the first mode passes.
    """
    usable = 0
    for k in range(1, triangular.shape[0] + 1):
        singular = np.linalg.svd(triangular[:k, :k], compute_uv=False)
        if singular[-1] <= 0:
            break
        kappa = (singular[0] / singular[-1]) ** 2
        gain = np.sqrt(np.mean(singular**-2.0))
        if kappa > limit / _ADVICE_MARGIN or gain > WELL_CONDITIONED_NOISE_GAIN:
            break
        usable = k
    return usable

def orthonormalise(
    columns: NDArray[np.float64], what: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """CholeskyQR2: ``columns = Q R`` with ``Q^T Q = N I`` (unit-RMS columns on the samples).

    Two passes of "Cholesky of the Gram matrix, then ``Q = H R^-1``" give Q orthonormal to
    rounding and a backward-stable R for kappa(H) up to about 1e8 (Fukaya, Nakatsukasa,
    Yanagisawa & Yamamoto 2014, "CholeskyQR2: a simple and communication-avoiding algorithm
    for computing a tall-skinny QR factorization"). The cost is two N x M x M products; the
    N x M matrix is never decomposed itself.

    Parameters
    ----------
    columns : ndarray, shape (N, M)
    what : str
        Name of the basis, for the error message.

    Returns
    -------
    Q : ndarray, shape (N, M)
    R : ndarray, shape (M, M), upper triangular with a positive diagonal

    Raises
    ------
    IllConditionedBasis
        If the columns are linearly dependent on the samples to working precision.
    """
    n = columns.shape[0]
    q = columns
    r_total = np.eye(columns.shape[1])
    for _ in range(2):
        r = cholesky_factor(q.T @ q / n, what, n)
        q = q @ scipy.linalg.solve_triangular(r, np.eye(r.shape[0]), lower=False)
        r_total = r @ r_total
    check_condition(r_total, what, n)
    return q, r_total


def cholesky_factor(gram: NDArray[np.float64], what: str, n: int) -> NDArray[np.float64]:
    """Upper Cholesky factor of ``gram`` (M x M, normalised by the N samples), or the error.

    Raises
    ------
    IllConditionedBasis
        If the columns are linearly dependent on the samples to working precision.
    """
    try:
        r = scipy.linalg.cholesky(gram, lower=False)
    except np.linalg.LinAlgError:
        r = None
    if r is None or not np.isfinite(r).all():
        raise IllConditionedBasis(
            f"{what}: the {gram.shape[0]} columns are linearly dependent on these "
            f"{n} samples; expected fewer modes or a larger aperture"
        )
    return r


def check_condition(r_total: NDArray[np.float64], what: str, n: int) -> None:
    """Refuse a factor whose kappa(G) exceeds :data:`MAX_GRAM_CONDITION`.

    Raises
    ------
    IllConditionedBasis
        Naming kappa(G), the limit and the usable mode count.
    """
    singular = np.linalg.svd(r_total, compute_uv=False)
    kappa = float((singular[0] / singular[-1]) ** 2)
    if not kappa <= MAX_GRAM_CONDITION:
        shown_kappa, _ = distinct_figures(kappa, MAX_GRAM_CONDITION)
        raise IllConditionedBasis(
            f"{what}: kappa(G) = {shown_kappa} on these {n} samples is above the limit "
            f"{MAX_GRAM_CONDITION:.17g} (1/eps = 2**52): these modes are numerically degenerate here",
            usable_modes=usable_mode_count(r_total),
        )


def factor_quality(triangular: NDArray[np.float64]) -> tuple[float, float]:
    """kappa(G) and noise gain of ``G = R^T R`` from its triangular factor.

    Parameters
    ----------
    triangular : ndarray, shape (M, M)
        R with ``H = Q R`` and ``Q^T Q = N I``, so ``H^T H / N = R^T R``.

    Returns
    -------
    kappa : float
        Condition number of G, from the singular values of R (more accurate than G's).
    gain : float
        ``sqrt(trace(G^-1) / M)``, the noise gain of :func:`~wavestack.pipeline.fit.conditioning.noise_gain`.
    """
    singular = np.linalg.svd(triangular, compute_uv=False)
    kappa = float((singular[0] / singular[-1]) ** 2)
    gain = float(np.sqrt(np.mean(singular**-2.0)))  # sqrt(trace(G^-1) / M)
    return kappa, gain
