"""What a fitter is and what it returns: the pupil, the basis, the diagnostics of a build, the
result of a fit, and the error raised for a frame that cannot be fitted.

All are frozen values; :class:`~wavestack.pipeline.fit.fitter.Fitter` makes them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from .physical_terms import PhysicalTerms

if TYPE_CHECKING:  # only for annotations: the results do not need the map's modules
    from ..mapping import CanonicalMap


NanPolicy = Literal["raise", "omit"]


class InvalidFrame(ValueError):
    """A frame that does not fit the fitter's aperture (wrong shape, NaN inside the aperture)."""


@dataclass(frozen=True)
class Pupil:
    """The circle that defines the unit disk, in pixels.

    Attributes
    ----------
    cx : float
        Centre column.
    cy : float
        Centre row.
    radius : float
        Radius in pixels.
    """

    cx: float
    cy: float
    radius: float

    def as_dict(self) -> dict[str, float]:
        """JSON-ready form."""
        return {"cx": self.cx, "cy": self.cy, "radius": self.radius}


@dataclass(frozen=True)
class FitBasis:
    """What the coefficients of a fit mean.

    Attributes
    ----------
    method : str
        How the basis was built ("circle", "qr", ...).
    ordering : str
        Index convention of the modes ("noll", "ansi" or "fringe").
    normalisation : str
        "rms" (unit RMS over the unit disk), "edge" (unit value at the edge), or
        "aperture-rms" (the ``qr`` basis: orthonormal, unit RMS over the aperture's samples).
    modes : tuple of (n, m)
        Radial order and signed azimuthal frequency of each coefficient, in order (for ``qr``,
        the Zernike mode each orthonormal column was built from).
    first_index : int
        Index of the first mode in the ordering (1 for Noll and Fringe, 0 for ANSI).
    pupil : Pupil
        The unit disk in pixels.
    annular_obscuration : float or None
        The obscuration ratio of the annular Zernike terms the coefficients refer to: the
        ``annulus`` method's, or for a map onto an annulus its inner radius; None for circle
        polynomials.
    """

    method: str
    ordering: str
    normalisation: str
    modes: tuple[tuple[int, int], ...]
    first_index: int
    pupil: Pupil
    annular_obscuration: float | None = None


@dataclass(frozen=True)
class FitterDiagnostics:
    """How well the aperture is sampled by the basis, and what the build cost.

    Attributes
    ----------
    method : str
        The fit method.
    topology : str
        The aperture's topology ("simply-connected", "doubly-connected", "unsupported").
    valid_pixels : int
        Samples in the fit.
    excluded_outside_pupil : int
        Valid pixels left out because they lie outside a user-given pupil.
    gram_condition : float
        kappa(G) of ``G = H^T H / N`` for unit-RMS modes (1 for ``qr``).
    noise_gain : float
        Coefficient noise amplification against an orthonormal basis (1 for ``qr``).
    timings : mapping of str to float
        Seconds per build stage, and "total" (mapped methods add ``map_*`` stages).
    flips, max_beltrami, p95_beltrami : int, float, float or None
        Mapped methods: flipped triangles and the Beltrami coefficient |mu| of the map.
    area_scale_p5, area_scale_p95 : float or None
        Mapped methods: 5th and 95th percentiles of the per-triangle area scale.
    r_in : float or None
        Inner radius of the canonical annulus (None for a disk or an unmapped method).
    csf_iterations : int or None
        Iterations of the curve-shortening flow (``csf-qcm``).
    mesh_vertices : int or None
        Vertices of the aperture mesh (mapped methods).
    fallback : str or None
        Why a mapped method fell back to ``qr``; None when no fallback happened.
    method_reason : str or None
        With ``method="auto"``: why ``method`` was chosen (the figure compared and its limit);
        None for a method asked for by name.
    refit : str
        How frames are projected: ``"moments"`` (separable Legendre moments, no operator) or
        ``"operator"`` (a stored N x M operator).
    moment_strips : int or None
        Moments only: boxes the fitted pixels were cut into (row strips, each cut again where it
        has a column without a fitted pixel, e.g. on both sides of a central hole).
    moment_amplification : float or None
        Moments only: the largest coefficient row sum, the factor by which float64 rounding of
        the moments reaches the coefficients (relative error about this times 1.1e-16).
    obscuration_source : str or None
        ``annulus`` only: ``"given"`` or ``"measured"`` (the largest circle concentric with the
        pupil free of valid pixels); the ratio itself is ``FitBasis.annular_obscuration``.
    """

    method: str
    topology: str
    valid_pixels: int
    excluded_outside_pupil: int
    gram_condition: float
    noise_gain: float
    timings: Mapping[str, float] = field(default_factory=dict)
    flips: int | None = None
    max_beltrami: float | None = None
    p95_beltrami: float | None = None
    area_scale_p5: float | None = None
    area_scale_p95: float | None = None
    r_in: float | None = None
    csf_iterations: int | None = None
    mesh_vertices: int | None = None
    fallback: str | None = None
    method_reason: str | None = None
    refit: str = "operator"
    moment_strips: int | None = None
    moment_amplification: float | None = None
    obscuration_source: str | None = None

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form (the CLI's names)."""
        values = dataclasses.asdict(self)
        values["timings"] = dict(self.timings)
        return values


@dataclass(frozen=True, eq=False)
class RefitState:
    """What a fit's normal equations were made of, kept so that it can be refitted without some samples
    (:mod:`~wavestack.pipeline.fit.sample_removal`); sizes of the terms, no per-sample array.

    Attributes
    ----------
    product : ndarray, shape (K,)
        ``A^T (w - shift)`` over the samples the fit used.
    squares, total : float
        ``|w - shift|^2`` and ``sum(w - shift)`` over them.
    shift : float
        The constant taken off every sample before the sums.
    dropped_gram : ndarray, shape (K, K), or None
        ``A^T A`` of the samples the fit left out (non-finite), None when it left none out.
    dropped_sums : ndarray, shape (K,), or None
        ``A^T 1`` of the same samples.
    dropped_count : int
    terms : ndarray, shape (K,)
        The solved terms: basis, then removed physical terms, in the stored orthonormal columns.
    """

    product: NDArray[np.float64]
    squares: float
    total: float
    shift: float
    dropped_gram: NDArray[np.float64] | None
    dropped_sums: NDArray[np.float64] | None
    dropped_count: int
    terms: NDArray[np.float64]


@dataclass(frozen=True)
class FitResult:
    """The fit of one frame.

    Attributes
    ----------
    coefficients : ndarray, shape (M,)
        Coefficients in the fitter's own basis (see ``basis``), in the frame's units.
    residual_rms : float
        RMS of the frame minus the fit (and minus removed physical terms) over the samples.
    valid_count : int
        Samples that entered the fit.
    nan_count : int
        Samples inside the aperture that were NaN or infinite and were omitted.
    basis : FitBasis
        What the coefficients mean.
    residual_pv : float or None
        Peak-to-valley of the residual; computed only when asked for.
    residual_map : ndarray, shape (rows, cols), or None
        The residual, NaN outside the fitted samples; only when asked for.
    circle_coefficients : ndarray, shape (M,), or None
        For ``qr``: the same fit expressed in Zernike circle polynomials over the pupil, in the
        requested ordering and normalisation.
    removed : PhysicalTerms or None
        Piston, tilt (and power) removed in physical coordinates before the fit.
    refit_state : RefitState or None
        What :meth:`Fitter.refit_without <wavestack.pipeline.fit.fitter.Fitter.refit_without>`
        needs of this fit; None where the fit kept none (that refit then projects the frame again).
    """

    coefficients: NDArray[np.float64]
    residual_rms: float
    valid_count: int
    nan_count: int
    basis: FitBasis
    residual_pv: float | None = None
    residual_map: NDArray[np.float64] | None = None
    circle_coefficients: NDArray[np.float64] | None = None
    removed: PhysicalTerms | None = None
    refit_state: RefitState | None = field(default=None, repr=False, compare=False)
