"""``build_fitter``: from an aperture to a ready :class:`~wavestack.pipeline.fit.fitter.Fitter`.

The work done once per aperture, in order:

1. the aperture and its pupil circle (default: the minimum enclosing circle of the valid
   pixels), and the samples (valid pixels, in unit-disk coordinates of the pupil);
2. the method's unit-RMS basis columns on the samples (:mod:`wavestack.pipeline.fit.methods`;
   for ``csf-qcm`` and ``conformal`` this builds the mesh and the map);
3. the columns orthonormalised on the samples, ``H = Q R`` by CholeskyQR2
   (:mod:`wavestack.pipeline.fit.orthonormal`), and the physical piston/tilt/power columns likewise
   when their removal is asked for;
4. the operator ``[Q | Q_E]`` in the fit dtype, stored in the order that makes the per-frame
   product fastest, the small normal equations, and the M x M maps from orthonormal
   coefficients to the method's own.

Nothing is ever decomposed at the size of the pixel matrix: the expensive part is a few
N x M x M products.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg
from numpy.typing import DTypeLike, NDArray

from .._checks import is_integer, one_of
from ..aperture import Aperture, Topology, UnsupportedAperture
from ..formats.limits import format_bytes, memory_budget_bytes
from ..zernike import default_normalisation, mode_list
from .annulus import annulus_obscuration, check_obscuration, with_obscuration_source
from .basis_meaning import fit_basis
from .auto import AUTO, BuildOne, advised_error, build_auto
from .coefficient_maps import CoefficientMaps, coefficient_maps
from .legendre_moments import MAX_AMPLIFICATION
from .moment_build import MOMENT_METHODS, MomentRequest, build_moment_fitter
from .operator_projection import OperatorProjection
from .fitter import Fitter
from .methods import METHODS, MappingOptions, Samples, method_columns
from .normal_equations import IllConditionedBasis, NormalEquations
from .orthonormal import orthonormalise
from .physical_terms import physical_term_basis, physical_term_names
from .results import FitterDiagnostics, Pupil
from .sampling import aperture_of, fit_mask_of, pupil_of, samples_of

if TYPE_CHECKING:
    from ..mapping import CanonicalMap

logger = logging.getLogger(__name__)

_ORDERINGS = ("noll", "ansi", "fringe")
_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))
_FALLBACKS = (None, "qr")

# Storage order of the operator, chosen for the one product a refit makes (``w @ A``), from
# OpenBLAS gemv on this project's machine, N = 630,548 samples, one thread, median ms
# (pixel-major A (N, M) / mode-major A^T (M, N) / numpy sum of A as the memory pass):
#   M = 36:  float32 4.3 / 4.5 / 4.6,   float64  7.7 / 10.2 / 7.2
#   M = 64:  float32 10.7 / 9.7 / 7.6,  float64 31.3 / 14.8 / 11.3
#   M = 231: float32 58 / 37 / 37,      float64  112 / 68 / 46
# Pixel-major wins only for few columns; past this count the operator is stored mode-major.
_PIXEL_MAJOR_MAX_COLUMNS = 48


def available_methods() -> tuple[str, ...]:
    """Names accepted by ``build_fitter(method=...)``: ``"auto"`` and the concrete methods."""
    return (AUTO, *METHODS)


def _stored_operator(orthonormal: NDArray[np.float64], dtype: np.dtype) -> NDArray[np.floating]:
    """The operator as an (N, M) array in the storage order that makes ``w @ A`` fastest.

    Above ``_PIXEL_MAJOR_MAX_COLUMNS`` columns the data are stored as a C-ordered (M, N) array
    and returned as its transposed view, which numpy hands to BLAS without a copy.
    """
    if orthonormal.shape[1] <= _PIXEL_MAJOR_MAX_COLUMNS:
        return np.ascontiguousarray(orthonormal, dtype=dtype)
    return np.ascontiguousarray(orthonormal.T, dtype=dtype).T


# The largest mode count a fitter is built for: Noll 1000 reaches radial order 44, beyond any
# interferometer's report (Zygo and 4D give 36 or 37 terms); the bound stops a typo (100000)
# before the basis is allocated. Bounds on the memory the basis takes are checked separately.
MAX_MODES = 1000
# Arrays of (samples x modes) float64 alive at once while a fitter is built: the basis values,
# their orthonormalised copy, and a work copy in the factorisation.
_BASIS_COPIES = 3


def check_basis_size(valid_pixels: int, modes: int, max_bytes: int | None = None) -> None:
    """Refuse a mode count above :data:`MAX_MODES` or a basis larger than the memory budget.

    Parameters
    ----------
    valid_pixels : int
        Samples of the fit (the aperture's valid pixels).
    modes : int
    max_bytes : int, optional
        Default: :func:`~wavestack.pipeline.formats.limits.memory_budget_bytes`.

    Raises
    ------
    ValueError
        Naming the mode count and the bound it exceeds.
    """
    if modes > MAX_MODES:
        raise ValueError(f"modes: expected at most {MAX_MODES} (Noll {MAX_MODES} reaches radial order 44), got {modes}")
    needed = _BASIS_COPIES * 8 * int(valid_pixels) * int(modes)
    limit = memory_budget_bytes() if max_bytes is None else max_bytes
    if needed > limit:
        raise ValueError(f"modes: {modes} modes on {valid_pixels} pixels need {format_bytes(needed)} to build, more "
                         f"than the memory budget of {format_bytes(limit)}; expected fewer modes or a smaller map")


def _check_arguments(
    method: str, modes: int, ordering: str, dtype: np.dtype, fallback: str | None, obscuration: float | None
) -> None:
    one_of(method, "method", (AUTO, *METHODS), voice="expected")
    if obscuration is not None:
        check_obscuration(obscuration)
        if method != "annulus":
            raise ValueError(f"obscuration: only the 'annulus' method takes an obscuration ratio, got method {method!r}")
    if not is_integer(modes) or modes < 1:
        raise ValueError(f"modes: expected a positive integer, got {modes!r}")
    one_of(ordering, "ordering", _ORDERINGS, voice="expected")
    if dtype not in _DTYPES:
        raise ValueError(f"dtype: expected float32 or float64, got {dtype}")
    if fallback not in _FALLBACKS:
        raise ValueError(f"fallback: expected None or 'qr', got {fallback!r}")


def _mapping_diagnostics(mapping: CanonicalMap | None) -> dict[str, object]:
    if mapping is None:
        return {}
    quality = mapping.quality
    return {
        "flips": quality.flips,
        "max_beltrami": quality.max_beltrami,
        "p95_beltrami": quality.p95_beltrami,
        "area_scale_p5": quality.area_scale_p5,
        "area_scale_p95": quality.area_scale_p95,
        "r_in": mapping.r_in,
        "csf_iterations": mapping.csf_iterations,
        "mesh_vertices": mapping.mesh.n_vertices,
    }


def build_fitter(
    aperture_or_mask: Aperture | NDArray,
    method: str = "circle",
    modes: int = 36,
    ordering: str = "noll",
    pupil: Pupil | tuple[float, float, float] | None = None,
    dtype: DTypeLike = np.float32,
    *,
    normalisation: str | None = None,
    remove: str | None = None,
    laplacian: str = "cotangent",
    mesh_vertices: int = 15000,
    angular_balance: bool = True,
    fallback: str | None = None,
    fit_mask: NDArray | None = None,
    refit: str = "auto",
    obscuration: float | None = None,
) -> Fitter:
    """Precompute everything needed to refit frames on one aperture.

    Parameters
    ----------
    aperture_or_mask : Aperture or ndarray of shape (rows, cols)
        The aperture, or a mask (non-zero = valid) to build it from.
    method : {"circle", "qr", "annulus", "conformal", "csf-qcm", "auto"}
        ``auto``: ``circle`` where the circle basis is well conditioned on the aperture (noise
        gain at most ``AUTO_MAX_NOISE_GAIN``), else ``csf-qcm`` (``qr`` for an aperture no map
        can handle); ``diagnostics.method`` is the method chosen and
        ``diagnostics.method_reason`` says why (:mod:`wavestack.pipeline.fit.auto`).
        ``circle``: Zernike polynomials over the pupil circle. ``qr``: the same modes
        orthonormalised over the samples; ``FitResult.circle_coefficients`` converts back.
        ``annulus``: annular Zernike polynomials (Mahajan), unit RMS over the annulus
        ``obscuration <= rho <= 1`` of the pupil circle, on the pixels themselves
        (``basis.annular_obscuration`` is the ratio used).
        ``csf-qcm``: Zernike (or annular Zernike) polynomials on the CSF-QCM map of the aperture
        onto the unit disk (or a concentric annulus). ``conformal``: the same on a discrete
        conformal map (the baseline).
    modes : int
        Number of modes: the first ``modes`` terms of ``ordering`` (36 Noll terms reach n = 7;
        231 reach n = 20).
    ordering : {"noll", "ansi", "fringe"}
        Index convention (see :mod:`wavestack.pipeline.zernike.indices`).
    pupil : Pupil or (cx, cy, r), optional
        The unit disk in pixels, cx a column and cy a row coordinate. Default: the aperture's
        minimum enclosing circle through the outermost valid pixel centres (also the outer
        circle of ``annulus``). Valid pixels outside
        a given pupil are left out of the fit (counted in ``diagnostics``). For mapped methods
        it only normalises the physical piston/tilt/power terms.
    dtype : {numpy.float32, numpy.float64}
        Type of the stored operator and the per-frame product; the factorisations are float64.
    normalisation : {"rms", "edge"}, optional
        Output normalisation of Zernike coefficients; default: the ordering's own (unit RMS for
        Noll and ANSI, unit edge value for Fringe). Annular terms (``annulus``, and ``csf-qcm`` on
        an annulus) are always unit RMS over their annulus.
    remove : {"ptt", "pttp"}, optional
        Fit and remove piston and tilt (and power) in physical coordinates before the fit; they
        are reported in ``FitResult.removed``.
    laplacian : {"cotangent", "graph"}
        Interior weights of the ``csf-qcm`` map (``graph`` is the paper-faithful mode).
    mesh_vertices : int
        Approximate vertex count of the aperture mesh of the mapped methods.
    angular_balance : bool
        ``csf-qcm`` only: balance the map's area over angle (our addition to the paper's
        method; False gives the paper's method alone).
    fallback : {None, "qr"}
        With "qr", an aperture a mapped method cannot handle (several components or holes)
        gives a ``qr`` fitter whose ``diagnostics.fallback`` says why, instead of an error.
    fit_mask : ndarray of shape (rows, cols), optional
        The pixels to fit (non-zero = fit), when they are not the aperture's: a measured map's
        own valid pixels, with drop-outs and isolated pixels, while the aperture is its clean
        outline. Default: the aperture's mask. The aperture still gives the default pupil; a
        mapped method maps the aperture trimmed to the fitted pixels (drop-outs filled, nothing
        past the outermost fitted pixels: :func:`~wavestack.pipeline.fit.map_domain.map_domain`),
        and fitted pixels outside that domain take the map's extrapolation from the nearest mesh
        triangle, clamped into the unit disk.
    refit : {"auto", "moments", "operator"}
        How frames are projected on the basis. ``auto``: by separable Legendre moments (one pass
        over the frame, no N x M operator; :mod:`wavestack.pipeline.fit.moment_projection`) for
        the polynomial methods ``circle`` and ``qr`` where the moments keep float64 precision
        (``diagnostics.moment_amplification`` at most 3e4), else by a stored operator (always
        for the mapped methods, whose columns are not polynomials). ``moments`` insists (raises
        where precision would be lost), ``operator`` keeps the operator. ``diagnostics.refit``
        says which was built. ``annulus`` is served like ``circle``.
    obscuration : float, optional
        ``annulus`` only: the obscuration ratio (inner over outer radius, 0 < obscuration < 1).
        Default: measured, the largest circle concentric with the pupil that holds no valid
        pixel centre (:func:`~wavestack.pipeline.fit.annulus.annulus_obscuration`); an aperture
        without a hole around the pupil centre is refused then. Pixels inside a given inner
        circle are fitted all the same (the polynomials are evaluated there as they are).

    Returns
    -------
    Fitter

    Raises
    ------
    ValueError
        For an invalid argument (the message names it), an empty aperture, a pupil that
        misses the aperture, or ``annulus`` without an obscuration on an aperture without a
        central hole.
    UnsupportedAperture
        For a mapped method on an aperture with several components or holes, without fallback.
    IllConditionedBasis
        If the modes are linearly dependent on the samples, or kappa(G) exceeds 2**52; the
        message (and ``advice``) names only remedies that were checked to build here.

    Examples
    --------
    A fitter for a 64 x 64 disk, then the fit of a map made of a quarter wave of defocus
    (Noll j = 4, unit RMS): the coefficient comes back.

    >>> import numpy as np
    >>> rows, cols = np.mgrid[:64, :64]
    >>> mask = (rows - 31.5) ** 2 + (cols - 31.5) ** 2 < 30**2
    >>> fitter = build_fitter(mask, modes=15, dtype=np.float64)
    >>> fitter.basis.modes[3]
    (2, 0)
    >>> truth = np.zeros(15)
    >>> truth[3] = 0.25
    >>> result = fitter.fit(fitter.surface(truth))
    >>> np.round(result.coefficients[:6], 6) + 0.0
    array([0.  , 0.  , 0.  , 0.25, 0.  , 0.  ])
    """
    dtype = np.dtype(dtype)
    _check_arguments(method, modes, ordering, dtype, fallback, obscuration)
    normalisation = normalisation or default_normalisation(ordering)
    if normalisation not in ("rms", "edge"):
        raise ValueError(f"normalisation: expected 'rms' or 'edge', got {normalisation!r}")
    if remove is not None:
        physical_term_names(remove)
    one_of(refit, "refit", ("auto", "moments", "operator"), voice="expected")
    options = MappingOptions(
        laplacian=laplacian, mesh_vertices=mesh_vertices, angular_balance=bool(angular_balance)
    )
    settings = dict(
        modes=int(modes), ordering=ordering, pupil=pupil, dtype=dtype,
        normalisation=normalisation, remove=remove, options=options, refit=refit, obscuration=obscuration,
    )
    check_basis_size(0, int(modes))  # the mode bound; the operator's memory is checked where one is built
    aperture = aperture_of(aperture_or_mask)
    settings["fit_mask"] = fit_mask_of(fit_mask, aperture)

    def build(concrete: str, **overrides: object) -> Fitter:
        return _build(aperture, concrete, **{**settings, **overrides})

    try:
        if method == AUTO:
            return build_auto(build, aperture)
        return _with_fallback(build, aperture, method, fallback)
    except IllConditionedBasis as error:
        if error.advice:
            raise
        failed = method
        if method == AUTO:  # what failed is the method auto chose
            failed = "qr" if aperture.topology is Topology.UNSUPPORTED else "csf-qcm"
        raise advised_error(error, build, failed, aperture, int(modes)) from None


def _with_fallback(build: BuildOne, aperture: Aperture, method: str, fallback: str | None) -> Fitter:
    """``build(method)``, or with ``fallback="qr"`` the ``qr`` fitter where a map cannot be made."""
    try:
        return build(method)
    except UnsupportedAperture as error:
        if fallback is None or method not in ("conformal", "csf-qcm"):
            raise
        logger.warning("%s cannot map this aperture (%s); falling back to qr", method, error)
        fitter = build("qr")
        fitter.diagnostics = dataclasses.replace(fitter.diagnostics, fallback=f"{method}: {error}")
        return fitter

def _build(
    aperture: Aperture,
    method: str,
    *,
    modes: int,
    ordering: str,
    pupil: Pupil | tuple[float, float, float] | None,
    dtype: np.dtype,
    normalisation: str,
    remove: str | None,
    options: MappingOptions,
    fit_mask: NDArray[np.bool_] | None,
    refit: str,
    obscuration: float | None,
) -> Fitter:
    started = time.perf_counter()
    resolved_pupil = pupil_of(aperture, pupil)
    mode_pairs = mode_list(ordering, modes)
    annular = annulus_obscuration(aperture, resolved_pupil, obscuration, fit_mask) if method == "annulus" else None
    ratio = None if annular is None else annular.ratio
    if method in MOMENT_METHODS and refit != "operator":
        basis, scale = fit_basis(method, ordering, normalisation, mode_pairs, resolved_pupil, ratio)
        fitter = build_moment_fitter(
            aperture, MomentRequest(method, basis, scale, remove, dtype, pupil is not None, fit_mask), started
        )
        if fitter is not None:
            return with_obscuration_source(fitter, annular)
        if refit == "moments":
            raise ValueError(f"refit: 'moments' would lose precision on this aperture (coefficient amplification "
                             f"above {MAX_AMPLIFICATION:g} even on the finest strips); expected refit='auto' or "
                             "'operator'")
    check_basis_size(aperture.valid_count, int(modes))
    samples = samples_of(aperture, resolved_pupil, pupil is not None, fit_mask)
    timings = {"aperture": time.perf_counter() - started}

    tick = time.perf_counter()
    columns = method_columns(method, aperture, samples, mode_pairs, options, ratio, fit_mask)
    timings["basis"] = time.perf_counter() - tick
    if columns.mapping is not None:
        timings.update({f"map_{stage}": seconds for stage, seconds in columns.mapping.timings.items()})
    ratio = columns.mapping.r_in if columns.mapping is not None else ratio
    basis, scale = fit_basis(method, ordering, normalisation, mode_pairs, resolved_pupil, ratio)

    tick = time.perf_counter()
    factors = _factorise(columns.values, method, scale, samples, remove, dtype)
    timings["factorise"] = time.perf_counter() - tick
    timings["total"] = time.perf_counter() - started

    diagnostics = FitterDiagnostics(
        method=method,
        topology=aperture.topology.value,
        valid_pixels=int(samples.x.size),
        excluded_outside_pupil=samples.excluded,
        gram_condition=factors.maps.kappa,
        noise_gain=factors.maps.gain,
        timings=timings,
        refit="operator",
        **_mapping_diagnostics(columns.mapping),
    )
    logger.info("built %s fitter: %d modes on %d samples, kappa(G)=%.3g, %.3f s",
                method, len(mode_pairs), samples.x.size, factors.maps.kappa, timings["total"])
    return with_obscuration_source(Fitter(
        aperture=aperture,
        projection=OperatorProjection(aperture.shape, samples.flat_index, factors.operator),
        equations=factors.equations,
        coefficient_transform=factors.maps.coefficient_transform,
        from_coefficients=factors.maps.from_coefficients,
        basis=basis,
        diagnostics=diagnostics,
        dtype=dtype,
        circle_transform=factors.maps.circle_transform,
        removal=remove,
        removal_transform=factors.removal_transform,
        mapping=columns.mapping,
    ), annular)


@dataclass(frozen=True)
class _Factors:
    """The stored operator, the normal equations and the coefficient maps of an operator build."""

    operator: NDArray[np.floating]
    equations: NormalEquations
    maps: CoefficientMaps
    removal_transform: NDArray[np.float64] | None


def _factorise(
    values: NDArray[np.float64],
    method: str,
    scale: NDArray[np.float64],
    samples: Samples,
    remove: str | None,
    dtype: np.dtype,
) -> _Factors:
    """Orthonormalise the method's columns (and the removed terms') on the samples (step 3)."""
    orthonormal, triangular = orthonormalise(values, method)
    removal_transform = None
    if remove is not None:
        terms = physical_term_basis(samples.x, samples.y, remove)
        terms_orthonormal, terms_triangular = orthonormalise(terms, f"remove={remove}")
        removal_transform = _inverse(terms_triangular)
        orthonormal = np.hstack([orthonormal, terms_orthonormal])
    operator = _stored_operator(orthonormal, dtype)
    equations = NormalEquations(
        orthonormal.T @ orthonormal, orthonormal.sum(axis=0), len(scale), samples.x.size
    )
    del orthonormal
    maps = coefficient_maps(method, scale, triangular, equations.gram, samples.x.size)
    return _Factors(operator, equations, maps, removal_transform)


def _inverse(triangular: NDArray[np.float64]) -> NDArray[np.float64]:
    return scipy.linalg.solve_triangular(triangular, np.eye(triangular.shape[0]), lower=False)
