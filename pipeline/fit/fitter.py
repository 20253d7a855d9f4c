"""A fitter: everything about one aperture precomputed, so a frame costs a gather and a product.

``build_fitter`` (module :mod:`wavestack.pipeline.fit.build`) does the expensive work once per
aperture; :class:`Fitter` then refits any frame on that aperture:

1. gather the valid samples ``w`` from the frame (one pass over the frame);
2. centre them on their mean (keeps float32 sums accurate; the mean returns through the piston);
3. ``b = A^T w`` with the stored operator ``A``, the basis orthonormalised on the samples
   (the one pass over the operator);
4. solve the small normal equations (:mod:`wavestack.pipeline.fit.normal_equations`) and map the
   orthonormal coefficients to the method's own with an M x M matrix.

The residual RMS comes from the normal-equation identity, so steps 1-4 are the whole per-frame
cost. The residual map and its peak-to-valley take one more pass and are computed on request.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from .normal_equations import NormalEquations, SolvedFrame
from .physical_terms import terms_from_vector
from .results import FitBasis, FitResult, FitterDiagnostics, InvalidFrame, NanPolicy

if TYPE_CHECKING:  # only for annotations: the fitter does not need the map's modules
    from ..mapping import CanonicalMap

logger = logging.getLogger(__name__)


class Fitter:
    """Refits frames on one aperture from a precomputed operator and factorisation.

    Built by :func:`wavestack.pipeline.build_fitter`; not meant to be constructed by hand.

    Parameters
    ----------
    aperture : Aperture
        The aperture the fitter was built for.
    flat_index : ndarray of intp, shape (N,)
        Row-major indices of the fitted samples in a frame.
    operator : ndarray, shape (N, M + k)
        The basis columns orthonormalised on the samples (unit RMS), followed by the
        orthonormalised physical-term columns, in the fit dtype.
    equations : NormalEquations
        The factorised normal equations of ``operator``.
    coefficient_transform : ndarray, shape (M, M)
        Maps solved (orthonormal) coefficients to ``FitResult.coefficients``.
    from_coefficients : ndarray, shape (M, M)
        The inverse map, used by :meth:`surface`.
    basis : FitBasis
        What the coefficients mean.
    diagnostics : FitterDiagnostics
        Sampling quality and build timings.
    circle_transform : ndarray, shape (M, M), optional
        Maps solved coefficients to circle-polynomial coefficients (``qr`` only).
    removal : str, optional
        "ptt" or "pttp" when physical terms are removed before the fit.
    removal_transform : ndarray, shape (k, k), optional
        Maps solved physical-term coefficients to piston, tilt (and power).
    mapping : CanonicalMap, optional
        The aperture map of a mapped method (``csf-qcm``, ``conformal``).
    """

    def __init__(
        self,
        *,
        aperture: Aperture,
        flat_index: NDArray[np.intp],
        operator: NDArray[np.floating],
        equations: NormalEquations,
        coefficient_transform: NDArray[np.float64],
        from_coefficients: NDArray[np.float64],
        basis: FitBasis,
        diagnostics: FitterDiagnostics,
        circle_transform: NDArray[np.float64] | None = None,
        removal: str | None = None,
        removal_transform: NDArray[np.float64] | None = None,
        mapping: CanonicalMap | None = None,
    ) -> None:
        self.aperture = aperture
        self.basis = basis
        self.diagnostics = diagnostics
        self.removal = removal
        self.mapping = mapping
        self._flat_index = flat_index
        self._operator = operator
        self._equations = equations
        self._coefficient_transform = coefficient_transform
        self._from_coefficients = from_coefficients
        self._circle_transform = circle_transform
        self._removal_transform = removal_transform

    @property
    def dtype(self) -> np.dtype:
        """Floating-point type of the stored operator and of the per-frame product."""
        return self._operator.dtype

    @property
    def n_modes(self) -> int:
        """M, the number of fitted coefficients."""
        return len(self.basis.modes)

    @property
    def operator(self) -> NDArray[np.floating]:
        """The stored operator ``[H | E]``, shape (N, M + k), read-only (the bytes a refit reads)."""
        view = self._operator.view()
        view.flags.writeable = False
        return view

    @property
    def operator_nbytes(self) -> int:
        """Bytes of the operator read once per frame."""
        return int(self._operator.nbytes)

    def __repr__(self) -> str:
        return (
            f"Fitter(method={self.basis.method!r}, modes={self.n_modes}, "
            f"ordering={self.basis.ordering!r}, samples={self._flat_index.size}, "
            f"dtype={self.dtype.name})"
        )

    def fit(
        self,
        frame: NDArray[np.floating],
        *,
        nan_policy: NanPolicy = "raise",
        residual: bool = False,
    ) -> FitResult:
        """Fit one frame.

        Parameters
        ----------
        frame : ndarray, shape (rows, cols)
            The map on the fitter's aperture, in any units (waves, nm, radians); values outside
            the aperture are ignored.
        nan_policy : {"raise", "omit"}
            What to do with NaN or infinite samples inside the aperture: raise
            :class:`InvalidFrame`, or fit without them (a rank-k downdate of the normal
            equations, reported as ``FitResult.nan_count``).
        residual : bool
            Also compute the residual map and its peak-to-valley (one more pass over the
            operator).

        Returns
        -------
        FitResult

        Raises
        ------
        InvalidFrame
            If the frame's shape differs from the aperture's, or it has non-finite samples
            inside the aperture with ``nan_policy="raise"``, or no finite sample at all.
        """
        samples = self._gather(frame)
        equations, bad = self._equations, None
        mean = float(samples.mean())
        if not np.isfinite(mean):
            bad = np.flatnonzero(~np.isfinite(samples))
            equations = self._equations_without(bad, nan_policy)
            samples[bad] = 0.0
            mean = float(samples.sum()) / equations.n_samples
        if not equations.constant_in_span:
            mean = 0.0  # centring is only exact when the basis holds a constant
        if bad is not None:
            samples[bad] = mean  # zero once centred: the dropped samples add nothing below
        samples -= samples.dtype.type(mean)
        product = (samples @ self._operator).astype(np.float64)
        solved = equations.solve(product, float(np.dot(samples, samples)), mean)
        return self._result(solved, samples, mean, bad, equations.n_samples, residual)

    def surface(self, coefficients: NDArray[np.floating]) -> NDArray[np.float64]:
        """Reconstruct the map a coefficient vector describes on this aperture.

        Parameters
        ----------
        coefficients : ndarray, shape (M,)
            Coefficients in this fitter's basis (as in ``FitResult.coefficients``).

        Returns
        -------
        ndarray, shape (rows, cols)
            The surface at the fitted samples, NaN elsewhere. Removed physical terms are not
            included.

        Raises
        ------
        ValueError
            If the vector has the wrong length.
        """
        values = self._operator[:, : self.n_modes] @ (self._from_coefficients @ self._checked(coefficients))
        return self._scatter(values)

    def surface_rms(self, coefficients: NDArray[np.floating]) -> float:
        """RMS over the fitted samples of the surface a coefficient vector describes.

        The same number as the RMS of :meth:`surface` (removed physical terms excluded), but from
        the orthonormal form: the stored basis columns have unit RMS and are mutually orthogonal
        on the samples, so the RMS of ``H a`` is ``|a|``. It costs an M x M product instead of a
        pass over the N x M operator.

        Parameters
        ----------
        coefficients : ndarray, shape (M,)
            Coefficients in this fitter's basis.

        Returns
        -------
        float
            RMS in the units of the coefficients.
        """
        return float(np.linalg.norm(self._from_coefficients @ self._checked(coefficients)))

    def _checked(self, coefficients: NDArray[np.floating]) -> NDArray[np.float64]:
        """A coefficient vector of this fitter's length, as float64."""
        coefficients = np.asarray(coefficients, dtype=np.float64)
        if coefficients.shape != (self.n_modes,):
            raise ValueError(
                f"coefficients: expected shape ({self.n_modes},), got {coefficients.shape}"
            )
        return coefficients

    def export_state(self) -> dict[str, object]:
        """Everything the per-frame path needs, as arrays and JSON-ready values.

        Used by :mod:`wavestack.pipeline.fit.store`; the operator is given in its storage
        order (``operator_mode_major`` says whether it is the transposed (M, N) array).
        """
        mode_major = not self._operator.flags.c_contiguous
        basis = dataclasses.asdict(self.basis)
        return {
            "flat_index": self._flat_index,
            "operator": self._operator.T if mode_major else self._operator,
            "operator_mode_major": np.array(mode_major),
            "gram": self._equations.gram,
            "column_sums": self._equations.column_sums,
            "n_basis": np.array(self._equations.n_basis),
            "n_samples": np.array(self._equations.n_samples),
            "coefficient_transform": self._coefficient_transform,
            "from_coefficients": self._from_coefficients,
            "circle_transform": self._circle_transform,
            "removal_transform": self._removal_transform,
            "removal": self.removal,
            "basis": basis,
            "diagnostics": self.diagnostics.as_dict(),
        }

    # -- per-frame helpers ------------------------------------------------------------------

    def _gather(self, frame: NDArray[np.floating]) -> NDArray[np.floating]:
        frame = np.asarray(frame)
        if frame.shape != self.aperture.shape:
            raise InvalidFrame(
                f"frame: expected shape {self.aperture.shape} like the fitter's aperture, "
                f"got {frame.shape}"
            )
        if not (np.issubdtype(frame.dtype, np.floating) or np.issubdtype(frame.dtype, np.integer)):
            raise InvalidFrame(f"frame: expected a real-valued array, got dtype {frame.dtype}")
        samples = np.take(frame.reshape(-1), self._flat_index)
        return samples.astype(self.dtype, copy=False)

    def _equations_without(self, bad: NDArray[np.intp], nan_policy: NanPolicy) -> NormalEquations:
        total = self._flat_index.size
        if nan_policy not in ("raise", "omit"):
            raise ValueError(f"nan_policy: expected 'raise' or 'omit', got {nan_policy!r}")
        if nan_policy == "raise":
            raise InvalidFrame(
                f"frame: {bad.size} of {total} samples inside the aperture are NaN or infinite; "
                "expected finite values (use nan_policy='omit' to fit without them)"
            )
        if total - bad.size <= self._operator.shape[1]:
            raise InvalidFrame(
                f"frame: only {total - bad.size} finite samples inside the aperture; expected "
                f"more than the {self._operator.shape[1]} fitted terms"
            )
        logger.debug("omitting %d non-finite samples by downdating the normal equations", bad.size)
        return self._equations.without_rows(self._operator[bad].astype(np.float64))

    def _result(
        self,
        solved: SolvedFrame,
        centred: NDArray[np.floating],
        mean: float,
        bad: NDArray[np.intp] | None,
        n_valid: int,
        residual: bool,
    ) -> FitResult:
        circle = None
        if self._circle_transform is not None:
            circle = self._circle_transform @ solved.basis
        removed = None
        if self.removal is not None and self._removal_transform is not None:
            pupil = self.basis.pupil
            removed = terms_from_vector(
                self._removal_transform @ solved.removed,
                self.removal,
                (pupil.cx, pupil.cy),
                pupil.radius,
            )
        residual_pv = residual_map = None
        if residual:
            residual_map, residual_pv = self._residual(solved, centred, mean, bad)
        return FitResult(
            coefficients=self._coefficient_transform @ solved.basis,
            residual_rms=float(np.sqrt(solved.residual_sq / n_valid)),
            valid_count=n_valid,
            nan_count=0 if bad is None else int(bad.size),
            basis=self.basis,
            residual_pv=residual_pv,
            residual_map=residual_map,
            circle_coefficients=circle,
            removed=removed,
        )

    def _residual(
        self,
        solved: SolvedFrame,
        centred: NDArray[np.floating],
        mean: float,
        bad: NDArray[np.intp] | None,
    ) -> tuple[NDArray[np.float64], float]:
        # The terms in the operator's own type: a float64 vector against a float32 operator would
        # make numpy copy the whole operator to float64 on every call (7x the cost of the pass).
        # The residual is then as exact as the operator (float32: ~1e-7 relative to the map).
        terms = np.concatenate([solved.basis, solved.removed]).astype(self._operator.dtype)
        centred_residual = centred - self._operator @ terms  # the mean cancels in the peak-to-valley
        if bad is not None:
            centred_residual[bad] = np.nan
            peak_to_valley = float(np.nanmax(centred_residual)) - float(np.nanmin(centred_residual))
        else:
            peak_to_valley = float(centred_residual.max()) - float(centred_residual.min())
        return self._scatter(centred_residual.astype(np.float64) + mean), peak_to_valley

    def _scatter(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        full = np.full(self.aperture.shape, np.nan)
        full.reshape(-1)[self._flat_index] = values
        return full
