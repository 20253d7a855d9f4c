"""The small dense algebra behind a refit: normal equations with optional physical-term removal.

A fitter stores one operator ``A = [H | E]`` of shape (N, M + k) on the aperture samples: the M
basis columns ``H`` and, when piston/tilt/power removal is configured, k physical-term columns
``E``. A frame then costs one product ``b = A^T w``; everything after it works on (M + k)-sized
vectors with matrices factorised once here:

* removal first, as interferometer software does it: ``d = (E^T E)^{-1} E^T w`` and
  ``w' = w - E d``, so ``H^T w' = b_H - (H^T E) d`` and ``|w'|^2 = |w|^2 - d . b_E``;
* the fit ``c = G^{-1} H^T w'`` with ``G = H^T H``. ``G^{-1}`` (and ``(E^T E)^{-1}``) are formed
  once from their Cholesky factors, so a frame costs a matrix-vector product. Numerically this
  is as good as a triangular solve here: every fitter's stored columns are orthonormalised on
  its samples, so ``G = N I`` up to rounding (kappa(G) = 1 + 4e-14 for a 36-mode disk) and a
  downdate for a few NaN samples moves it little; the product also avoids a LAPACK call per
  frame, which costs ~70 us when the caches are cold (measured);
* the residual from the normal-equation identity ``|w' - H c|^2 = |w'|^2 - c . H^T w'``, with no
  second pass over the operator.

Samples that turn out to be NaN in a frame are dropped by a rank-k downdate of the Gram matrix
(``K - A_k^T A_k``) rather than by rebuilding the fitter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .projection import Downdate


# The removed terms of a fit without removal: shared, so read-only.
_NO_TERMS = np.zeros(0)
_NO_TERMS.flags.writeable = False


class IllConditionedBasis(ValueError):
    """The basis is numerically rank-deficient on the samples (too many modes for the aperture).

    Parameters
    ----------
    message : str
        What failed, with the figures compared.
    usable_modes : int, optional
        The largest number of leading modes whose kappa(G) stays a hundredfold below the limit
        on these samples (computed from the same factor), or None when not known.
    advice : tuple of (str, object), optional
        Settings that avoid the failure, as (setting, value) pairs, e.g.
        ``(("method", "csf-qcm"), ("modes", 15))``; the message already names them, a command
        line may reword them as its own options.
    """

    def __init__(
        self,
        message: str,
        *,
        usable_modes: int | None = None,
        advice: tuple[tuple[str, object], ...] = (),
    ) -> None:
        super().__init__(message)
        self.usable_modes = usable_modes
        self.advice = advice


def _inverse(matrix: NDArray[np.float64], what: str) -> NDArray[np.float64]:
    """The inverse of a symmetric positive definite matrix, from its Cholesky factor."""
    try:
        factor = scipy.linalg.cho_factor(matrix, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        raise IllConditionedBasis(
            f"{what}: the Gram matrix is not positive definite on these samples; "
            "expected fewer modes or a larger aperture"
        ) from None
    return scipy.linalg.cho_solve(factor, np.eye(matrix.shape[0]), check_finite=False)


@dataclass(frozen=True)
class SolvedFrame:
    """Solution of one frame's normal equations (float64).

    Attributes
    ----------
    basis : ndarray, shape (M,)
        Coefficients of the basis columns.
    removed : ndarray, shape (k,)
        Coefficients of the removed physical-term columns (empty without removal).
    residual_sq : float
        Sum of squared residuals, clamped at zero.
    """

    basis: NDArray[np.float64]
    removed: NDArray[np.float64]
    residual_sq: float


class NormalEquations:
    """Factorised normal equations of an operator ``A = [H | E]`` on N samples.

    Parameters
    ----------
    gram : ndarray, shape (M + k, M + k)
        ``A^T A`` in float64.
    column_sums : ndarray, shape (M + k,)
        ``A^T 1``, used to restore the piston after the data were centred.
    n_basis : int
        M, the number of basis columns; the last ``k = gram.shape[0] - M`` columns are removed
        before the fit.
    n_samples : int
        N.

    Raises
    ------
    IllConditionedBasis
        If ``H^T H`` or ``E^T E`` is not positive definite.
    """

    def __init__(
        self,
        gram: NDArray[np.float64],
        column_sums: NDArray[np.float64],
        n_basis: int,
        n_samples: int,
    ) -> None:
        self.gram = gram
        self.column_sums = column_sums
        self.n_basis = n_basis
        self.n_samples = n_samples
        m = n_basis
        self._basis_inverse = _inverse(gram[:m, :m], "basis")
        self._has_removal = gram.shape[0] > m
        if self._has_removal:
            self._removal_inverse = _inverse(gram[m:, m:], "physical terms")
            self._cross = gram[:m, m:]
        # The response to a constant frame: a frame is centred before the product (which keeps
        # float32 sums accurate) and its mean added back through this linear response.
        self.constant_response = SolvedFrame(*self._solve_centred(column_sums, float(n_samples)))
        self.constant_in_span = self.constant_response.residual_sq <= 1e-9 * n_samples

    @property
    def has_removal(self) -> bool:
        """Whether physical-term columns are removed before the fit (k > 0)."""
        return self._has_removal

    @property
    def basis_inverse(self) -> NDArray[np.float64]:
        """``G^{-1}`` (M x M) of the basis columns, read-only."""
        view = self._basis_inverse.view()
        view.flags.writeable = False
        return view

    def solve(self, b: NDArray[np.float64], ww: float, mean: float) -> SolvedFrame:
        """Solve for a frame given ``b = A^T (w - mean)`` and ``ww = |w - mean|^2``.

        Parameters
        ----------
        b : ndarray, shape (M + k,)
            Product of the operator with the centred samples.
        ww : float
            Squared norm of the centred samples.
        mean : float
            The value subtracted from the samples before the product (0 if none).

        Returns
        -------
        SolvedFrame
        """
        basis, removed, residual_sq = self._solve_centred(b, ww)
        if mean != 0.0:
            basis = basis + mean * self.constant_response.basis
            if self._has_removal:
                removed = removed + mean * self.constant_response.removed
        return SolvedFrame(basis=basis, removed=removed, residual_sq=residual_sq)

    def _solve_centred(self, b: NDArray[np.float64], ww: float
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """Basis and removed coefficients of centred samples, and the residual sum of squares."""
        if not self._has_removal:  # the usual case, in as few numpy calls as it takes (~1 us each)
            basis = self._basis_inverse @ b
            return basis, _NO_TERMS, max(ww - float(basis @ b), 0.0)
        m = self.n_basis
        removed = self._removal_inverse @ b[m:]
        b_basis = b[:m] - self._cross @ removed
        ww = ww - float(removed @ b[m:])
        basis = self._basis_inverse @ b_basis
        return basis, removed, max(ww - float(basis @ b_basis), 0.0)

    def without(self, dropped: Downdate) -> NormalEquations:
        """Normal equations with some samples removed, given their share (a rank-k downdate).

        Parameters
        ----------
        dropped : Downdate
            ``A_k^T A_k``, ``A_k^T 1`` and the count of the samples to drop.

        Returns
        -------
        NormalEquations
        """
        return NormalEquations(
            self.gram - dropped.gram,
            self.column_sums - dropped.column_sums,
            self.n_basis,
            self.n_samples - dropped.count,
        )

    def without_rows(self, rows: NDArray[np.float64]) -> NormalEquations:
        """Normal equations with some samples removed (rank-k downdate).

        Parameters
        ----------
        rows : ndarray, shape (k, M + k_removal)
            The operator rows of the samples to drop, in float64.

        Returns
        -------
        NormalEquations
        """
        return NormalEquations(
            self.gram - rows.T @ rows,
            self.column_sums - rows.sum(axis=0),
            self.n_basis,
            self.n_samples - rows.shape[0],
        )

