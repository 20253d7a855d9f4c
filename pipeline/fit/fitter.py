"""A fitter: everything about one aperture precomputed, so a frame costs one pass and a small solve.

``build_fitter`` (module :mod:`wavestack.pipeline.fit.build`) does the expensive work once per
aperture; :class:`Fitter` then refits any frame on that aperture:

1. ``b = A^T (w - s)`` and ``|w - s|^2`` over the fitted samples, by one of two projections
   (:mod:`wavestack.pipeline.fit.projection`): separable Legendre moments of the frame for the
   polynomial bases (one pass over the frame, no operator), or a stored operator ``A`` (the
   mapped bases); ``A`` is the basis orthonormalised on the samples, plus the removed physical
   terms;
2. the constant ``s`` moved to the samples' mean (keeps the sums accurate; the mean returns
   through the piston);
3. solve the small normal equations (:mod:`wavestack.pipeline.fit.normal_equations`) and map the
   orthonormal coefficients to the method's own with an M x M matrix.

The residual RMS comes from the normal-equation identity, so steps 1-3 are the whole per-frame
cost. The residual map and its peak-to-valley take one more pass and are computed on request;
with them the RMS is taken from the map itself (the identity ``|w|^2 - c.b`` cancels: with a
float32 operator it rounds by a few per cent of a residual much smaller than the map).
Where the moments come from the run pass (small apertures, degree <= 7) and no physical terms
are removed, steps 1-3 are one compiled call (:mod:`wavestack.pipeline.fit.run_refit`), with or
without the residual map.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import TYPE_CHECKING, Union

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from .moment_projection import MomentProjection
from .normal_equations import NormalEquations, SolvedFrame
from .operator_projection import OperatorProjection
from .physical_terms import terms_from_vector
from .projection import Projected, check_frames
from .results import FitBasis, FitResult, FitterDiagnostics, NanPolicy
from .run_refit import RunFit, RunRefit
from .sample_removal import refit_state, refit_without

if TYPE_CHECKING:  # only for annotations: the fitter does not need the map's modules
    from ..mapping import CanonicalMap

logger = logging.getLogger(__name__)

Projection = Union[MomentProjection, OperatorProjection]


class Fitter:
    """Refits frames on one aperture from a precomputed projection and factorisation.

    Built by :func:`wavestack.pipeline.build_fitter`; not meant to be constructed by hand.

    Parameters
    ----------
    aperture : Aperture
        The aperture the fitter was built for.
    projection : MomentProjection or OperatorProjection
        How ``A^T w`` is made from a frame (:mod:`wavestack.pipeline.fit.projection`); ``A`` is
        the basis columns orthonormalised on the samples (unit RMS), followed by the
        orthonormalised physical-term columns.
    equations : NormalEquations
        The factorised normal equations of ``A``.
    coefficient_transform : ndarray, shape (M, M)
        Maps solved (orthonormal) coefficients to ``FitResult.coefficients``.
    from_coefficients : ndarray, shape (M, M)
        The inverse map, used by :meth:`surface`.
    basis : FitBasis
        What the coefficients mean.
    diagnostics : FitterDiagnostics
        Sampling quality and build timings.
    dtype : numpy dtype
        The fit dtype asked for (the operator's; the moment path always sums in float64).
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
        projection: Projection,
        equations: NormalEquations,
        coefficient_transform: NDArray[np.float64],
        from_coefficients: NDArray[np.float64],
        basis: FitBasis,
        diagnostics: FitterDiagnostics,
        dtype: np.dtype,
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
        self._projection = projection
        self._dtype = np.dtype(dtype)
        self._equations = equations
        self._coefficient_transform = coefficient_transform
        self._from_coefficients = from_coefficients
        self._circle_transform = circle_transform
        self._removal_transform = removal_transform
        self._run_refit = None  # small frames of polynomial bases: the whole refit in one compiled call
        if isinstance(projection, MomentProjection):
            maps = [m for m in (coefficient_transform, circle_transform) if m is not None]
            self._run_refit = RunRefit.serving(projection, equations, np.stack(maps))

    @property
    def dtype(self) -> np.dtype:
        """The fit dtype: the stored operator's (the moment path sums in float64 whatever it is)."""
        return self._dtype

    @property
    def n_modes(self) -> int:
        """M, the number of fitted coefficients."""
        return len(self.basis.modes)

    @property
    def refit(self) -> str:
        """How a frame is projected: ``"moments"`` (no operator) or ``"operator"``."""
        return "moments" if isinstance(self._projection, MomentProjection) else "operator"

    @property
    def operator(self) -> NDArray[np.floating]:
        """The stored operator ``[H | E]``, shape (N, M + k), read-only (the bytes a refit reads).

        Raises
        ------
        AttributeError
            For a fitter that refits by moments: it keeps no operator (build it with
            ``refit="operator"`` to have one).
        """
        if not isinstance(self._projection, OperatorProjection):
            raise AttributeError("operator: this fitter refits by separable moments and keeps no operator; "
                                 "build it with refit='operator' to have one")
        view = self._projection.operator.view()
        view.flags.writeable = False
        return view

    @property
    def operator_nbytes(self) -> int:
        """Bytes of the stored arrays read once per frame besides the frame (operator or tables)."""
        return self._projection.nbytes

    def __repr__(self) -> str:
        return (
            f"Fitter(method={self.basis.method!r}, modes={self.n_modes}, "
            f"ordering={self.basis.ordering!r}, samples={self._projection.n_samples}, "
            f"dtype={self.dtype.name}, refit={self.refit!r})"
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
            Also compute the residual map and its peak-to-valley (one more pass).

        Returns
        -------
        FitResult

        Raises
        ------
        InvalidFrame
            If the frame's shape differs from the aperture's, or it has non-finite samples
            inside the aperture with ``nan_policy="raise"``, or too few finite samples.
        """
        if nan_policy not in ("raise", "omit"):
            raise ValueError(f"nan_policy: expected 'raise' or 'omit', got {nan_policy!r}")
        if self._run_refit is not None:
            fitted = self._run_refit.fit(frame)
            if fitted is not None:  # else a sample is not finite: the general path applies the policy
                return self._run_result(frame, fitted, residual)
        projected = self._projection.project(frame, nan_policy)
        return self._finish(frame, projected, residual)

    def fit_many(
        self,
        frames: NDArray[np.floating],
        *,
        nan_policy: NanPolicy = "raise",
        residual: bool = False,
    ) -> list[FitResult]:
        """Fit a stack of frames: the same results as :meth:`fit` on each, in one product per block.

        Parameters
        ----------
        frames : ndarray, shape (K, rows, cols)
            The maps, stacked.
        nan_policy, residual
            As for :meth:`fit`; a frame with non-finite samples inside the aperture is fitted
            on its own under ``nan_policy``.

        Returns
        -------
        list of FitResult, length K

        Raises
        ------
        InvalidFrame
            If the stack's shape is not (K, rows, cols) of the aperture, or as :meth:`fit`.

        Examples
        --------
        >>> import numpy as np
        >>> from wavestack.pipeline import build_fitter
        >>> rows, cols = np.mgrid[:48, :48]
        >>> fitter = build_fitter((rows - 23.5) ** 2 + (cols - 23.5) ** 2 < 22**2, modes=10, dtype=np.float64)
        >>> truth = np.eye(10)[:3] * 0.1
        >>> frames = np.stack([np.nan_to_num(fitter.surface(t)) for t in truth])
        >>> results = fitter.fit_many(frames)
        >>> [round(float(r.coefficients[i]), 9) for i, r in enumerate(results)]
        [0.1, 0.1, 0.1]
        """
        if nan_policy not in ("raise", "omit"):
            raise ValueError(f"nan_policy: expected 'raise' or 'omit', got {nan_policy!r}")
        if self._run_refit is not None:  # frame by frame, as fit() does
            return [self.fit(frame, nan_policy=nan_policy, residual=residual)
                    for frame in check_frames(frames, self._projection.shape)]
        projected = self._projection.project_many(frames, keep_samples=residual)
        frames = np.asarray(frames)
        return [self.fit(frames[i], nan_policy=nan_policy, residual=residual) if p is None
                else self._finish(frames[i], p, residual) for i, p in enumerate(projected)]

    def _finish(self, frame: NDArray, projected: Projected, residual: bool) -> FitResult:
        """Solve the normal equations of a projected frame and make its result."""
        equations = self._equations
        if projected.downdate is not None:
            equations = equations.without(projected.downdate)
        n_valid = equations.n_samples
        mean = projected.shift + projected.total / n_valid
        centre = mean if equations.constant_in_span else 0.0  # centring is exact only with a constant
        step = centre - projected.shift
        product = projected.product - step * equations.column_sums
        squares = projected.squares - 2.0 * step * projected.total + n_valid * step * step
        solved = equations.solve(product, squares, centre)
        return self._result(solved, frame, projected, n_valid, residual)

    def refit_without(
        self,
        frame: NDArray[np.floating],
        fit: FitResult,
        dropped: NDArray[np.bool_],
        *,
        residual: bool = False,
    ) -> FitResult:
        """Refit a frame without some of the samples a fit of it used: a rank-k downdate of that fit.

        The result of fitting the frame with the dropped samples NaN (``nan_policy="omit"``), to
        rounding, from k operator rows and an (M + k)-sized solve: no pass over the frame or the
        operator; the residual RMS and PV exact, the residual map (one pass) on request
        (:mod:`wavestack.pipeline.fit.sample_removal`).

        Parameters
        ----------
        frame : ndarray, shape (rows, cols)
            The frame ``fit`` was made of, as it was (the dropped samples still hold their values).
        fit : FitResult
            This fitter's fit of ``frame``, made with ``residual=True``.
        dropped : ndarray of bool, shape (rows, cols)
            The samples to leave out; each must be one ``fit`` used.
        residual : bool
            Also make the new residual map (NaN at the dropped samples).

        Returns
        -------
        FitResult
            Its ``nan_count`` counts the first fit's omitted samples and the dropped ones.

        Raises
        ------
        ValueError
            If ``fit`` has no residual map or is another fitter's, or ``dropped`` is not a boolean
            map of the frame's shape marking only samples ``fit`` used.
        InvalidFrame
            If too few samples would be left to fit.

        Examples
        --------
        >>> import numpy as np
        >>> from wavestack.pipeline import build_fitter
        >>> y, x = np.mgrid[-1:1:48j, -1:1:48j]
        >>> fitter = build_fitter(np.hypot(x, y) < 0.95, modes=10, dtype=np.float64)
        >>> frame = np.nan_to_num(fitter.surface(np.eye(10)[4] * 0.1))
        >>> frame[24, 24] += 5.0  # a spike
        >>> fit = fitter.fit(frame, residual=True)
        >>> spike = np.zeros(frame.shape, dtype=bool); spike[24, 24] = True
        >>> refit = fitter.refit_without(frame, fit, spike)
        >>> round(float(refit.coefficients[4]), 9), round(refit.residual_rms, 6), refit.nan_count
        (0.1, 0.0, 1)
        """
        if fit.basis != self.basis:
            raise ValueError(f"fit: expected a fit by this fitter ({self.basis.method}, {self.n_modes} modes), "
                             f"got one by {fit.basis.method} with {len(fit.basis.modes)} modes")
        return refit_without(frame, fit, dropped, residual, columns=self._projection, equations=self._equations,
                             solved_result=lambda frame, projected: self._finish(frame, projected, False))

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
        terms = np.zeros(self._projection.n_columns)
        terms[: self.n_modes] = self._from_coefficients @ self._checked(coefficients)
        return self._projection.evaluate(terms)

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

        Used by :mod:`wavestack.pipeline.fit.store`. An operator fitter gives its operator in its
        storage order (``operator_mode_major`` says whether it is the transposed (M, N) array) and
        its sample indices; a moment fitter gives its fitted-pixel mask, strips and coefficients.
        """
        basis = dataclasses.asdict(self.basis)
        state: dict[str, object] = {
            "gram": self._equations.gram,
            "column_sums": self._equations.column_sums,
            "n_basis": np.array(self._equations.n_basis),
            "n_samples": np.array(self._equations.n_samples),
            "coefficient_transform": self._coefficient_transform,
            "from_coefficients": self._from_coefficients,
            "circle_transform": self._circle_transform,
            "removal_transform": self._removal_transform,
            "removal": self.removal,
            "dtype": self.dtype.name,
            "basis": basis,
            "diagnostics": self.diagnostics.as_dict(),
        }
        projection = self._projection
        if isinstance(projection, MomentProjection):
            moments = projection.state
            state.update(moment_mask_bits=np.packbits(moments.mask), moment_strips=moments.strips,
                         moment_degree=np.array(moments.degree), moment_transform=moments.transform)
        else:
            mode_major = not projection.operator.flags.c_contiguous
            state.update(flat_index=projection.flat_index,
                         operator=projection.operator.T if mode_major else projection.operator,
                         operator_mode_major=np.array(mode_major))
        return state

    # -- per-frame helpers ------------------------------------------------------------------

    def _run_result(self, frame: NDArray, fitted: RunFit, residual: bool) -> FitResult:
        """The result of the one-call refit (the residual map, when asked for, by one evaluation)."""
        n_valid = self._equations.n_samples
        residual_sq, residual_pv, residual_map = fitted.residual_sq, None, None
        if residual:  # the moment projection's residual needs the frame and the terms only
            residual_map, residual_pv, residual_sq = self._projection.residual(frame, None, fitted.solved)
        return FitResult(coefficients=fitted.mapped[0], residual_rms=math.sqrt(residual_sq / n_valid),
                         valid_count=n_valid, nan_count=0, basis=self.basis, residual_pv=residual_pv,
                         residual_map=residual_map,
                         circle_coefficients=fitted.mapped[1] if self._circle_transform is not None else None)

    def _result(
        self,
        solved: SolvedFrame,
        frame: NDArray,
        projected: Projected,
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
        residual_sq = solved.residual_sq
        terms = np.concatenate([solved.basis, solved.removed])
        if residual:  # the residual's own sum of squares: exact where the identity rounds (float32)
            residual_map, residual_pv, residual_sq = self._projection.residual(frame, projected, terms)
        return FitResult(
            coefficients=self._coefficient_transform @ solved.basis,
            residual_rms=math.sqrt(residual_sq / n_valid),
            valid_count=n_valid,
            nan_count=0 if projected.downdate is None else projected.downdate.count,
            basis=self.basis,
            residual_pv=residual_pv,
            residual_map=residual_map,
            circle_coefficients=circle,
            removed=removed,
            refit_state=refit_state(projected, terms),
        )
