"""``build_fitter``: from an aperture to a ready :class:`~wavestack.pipeline.fitter.Fitter`.

Each method turns the aperture's valid pixels into a set of basis columns on those samples:

* ``circle``: Zernike circle polynomials over the pupil circle (default: the aperture's minimum
  enclosing circle), the usual interferometer-software fit;
* ``qr``: the same modes orthonormalised over the aperture's samples (Gram-Schmidt, Swantner &
  Chow 1994, Appl. Opt. 33, 1832), done as CholeskyQR2 on the Gram matrix rather than a full
  SVD or Householder QR of the pixel matrix (Fukaya et al. 2014: two Cholesky passes give an
  orthogonality error at the level of rounding for kappa(H) up to about 1e8).

Every method then stores the same thing: its columns orthonormalised on the samples
(``H = Q R``, CholeskyQR2) with ``R`` kept to convert coefficients. A refit projects onto ``Q``,
whose Gram matrix is the identity, so its error grows with kappa(H) and not with
kappa(G) = kappa(H)^2 as a Cholesky solve of ``H^T H`` would (measured on a 3.5:1 rectangle,
36 modes, kappa(G) = 3.4e10: normal equations lose 3.6e-8 of 0.02-wave coefficients, the
orthonormal route 1e-13). The expensive part is two N x M x M products and a few M x M
factorisations; nothing is ever decomposed at the size of the pixel matrix.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import DTypeLike, NDArray

from .aperture import Aperture
from .conditioning import gram_condition, noise_gain, normalised_gram
from .fitter import FitBasis, Fitter, FitterDiagnostics, Pupil
from .normal_equations import NormalEquations, IllConditionedBasis
from .physical_terms import physical_term_basis, physical_term_names
from .zernike import zernike_basis
from .zernike_index import default_normalisation, mode_list, normalisation_factor

logger = logging.getLogger(__name__)

_ORDERINGS = ("noll", "ansi", "fringe")
_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))
# A user-given pupil may cut the aperture; samples farther out than this are left out.
_PUPIL_TOLERANCE = 1e-9


@dataclass(frozen=True)
class _Samples:
    """The valid pixels of an aperture in unit-disk coordinates of the pupil."""

    flat_index: NDArray[np.intp]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    excluded: int


@dataclass(frozen=True)
class _Method:
    """How a method turns samples into basis columns, and whether its output is orthonormal.

    ``columns`` returns the unit-RMS basis ``H`` of shape (N, M) on the samples. With
    ``orthonormal_output`` the fit reports coefficients of the orthonormalised columns (``qr``)
    and converts them to the basis' own coefficients as ``circle_coefficients``; otherwise it
    reports the basis' own coefficients directly.
    """

    columns: Callable[[_Samples, list[tuple[int, int]]], NDArray[np.float64]]
    orthonormal_output: bool


def _circle_columns(samples: _Samples, modes: list[tuple[int, int]]) -> NDArray[np.float64]:
    return zernike_basis(modes, samples.x, samples.y, normalisation="rms")


_METHODS: dict[str, _Method] = {
    "circle": _Method(_circle_columns, orthonormal_output=False),
    "qr": _Method(_circle_columns, orthonormal_output=True),
}

# Largest condition number of the sampled basis H (kappa(G) is its square) that still gives
# meaningful coefficients: CholeskyQR2 is accurate up to about eps**-0.5 (Fukaya et al. 2014),
# and past it the coefficients' noise gain exceeds 1e7 anyway.
_MAX_BASIS_CONDITION = float(np.finfo(np.float64).eps) ** -0.5


def available_methods() -> tuple[str, ...]:
    """Names accepted by ``build_fitter(method=...)``."""
    return tuple(_METHODS)


def _orthonormalise(
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
        try:
            r = scipy.linalg.cholesky(q.T @ q / n, lower=False)
        except np.linalg.LinAlgError:
            r = None
        if r is None or not np.isfinite(r).all():
            raise IllConditionedBasis(
                f"{what}: the {columns.shape[1]} columns are linearly dependent on these "
                f"{n} samples; expected fewer modes or a larger aperture"
            )
        q = q @ scipy.linalg.solve_triangular(r, np.eye(r.shape[0]), lower=False)
        r_total = r @ r_total
    singular = np.linalg.svd(r_total, compute_uv=False)
    if singular[0] > _MAX_BASIS_CONDITION * singular[-1]:
        raise IllConditionedBasis(
            f"{what}: kappa(G) = {(singular[0] / singular[-1]) ** 2:.3g} on these {n} samples; "
            f"expected at most {_MAX_BASIS_CONDITION ** 2:.1g} (use fewer modes or method 'qr' "
            "with fewer modes)"
        )
    return q, r_total


# Storage order of the operator, chosen for the one product a refit makes (``w @ A``), from
# OpenBLAS gemv on this project's machine, N = 630,548 samples, one thread, median ms
# (pixel-major A (N, M) / mode-major A^T (M, N) / numpy sum of A as the memory pass):
#   M = 36:  float32 4.3 / 4.5 / 4.6,   float64  7.7 / 10.2 / 7.2
#   M = 64:  float32 10.7 / 9.7 / 7.6,  float64 31.3 / 14.8 / 11.3
#   M = 231: float32 58 / 37 / 37,      float64  112 / 68 / 46
# Pixel-major wins only for few columns; past this count the operator is stored mode-major.
_PIXEL_MAJOR_MAX_COLUMNS = 48


def _stored_operator(orthonormal: NDArray[np.float64], dtype: np.dtype) -> NDArray[np.floating]:
    """The operator as an (N, M) array in the storage order that makes ``w @ A`` fastest.

    Above ``_PIXEL_MAJOR_MAX_COLUMNS`` columns the data are stored as a C-ordered (M, N) array
    and returned as its transposed view, which numpy hands to BLAS without a copy.
    """
    if orthonormal.shape[1] <= _PIXEL_MAJOR_MAX_COLUMNS:
        return np.ascontiguousarray(orthonormal, dtype=dtype)
    return np.ascontiguousarray(orthonormal.T, dtype=dtype).T


def _factor_quality(triangular: NDArray[np.float64]) -> tuple[float, float]:
    """kappa(G) and noise gain of ``G = R^T R`` from its triangular factor (singular values of R)."""
    singular = np.linalg.svd(triangular, compute_uv=False)
    kappa = float((singular[0] / singular[-1]) ** 2)
    gain = float(np.sqrt(np.mean(singular**-2.0)))  # sqrt(trace(G^-1) / M)
    return kappa, gain


def _aperture_of(aperture_or_mask: Aperture | NDArray) -> Aperture:
    if isinstance(aperture_or_mask, Aperture):
        return aperture_or_mask
    return Aperture.from_mask(np.asarray(aperture_or_mask))


def _pupil_of(aperture: Aperture, pupil: Pupil | tuple[float, float, float] | None) -> Pupil:
    if pupil is None:
        return Pupil(*aperture.enclosing_circle())
    if not isinstance(pupil, Pupil):
        values = tuple(pupil)
        if len(values) != 3:
            raise ValueError(f"pupil: expected (cx, cy, r) in pixels, got {pupil!r}")
        pupil = Pupil(*(float(v) for v in values))
    if not (np.isfinite([pupil.cx, pupil.cy, pupil.radius]).all() and pupil.radius > 0):
        raise ValueError(f"pupil: expected finite centre and a radius > 0 pixels, got {pupil}")
    return pupil


def _samples_of(aperture: Aperture, pupil: Pupil, user_pupil: bool) -> _Samples:
    rows, cols = np.nonzero(aperture.mask)
    x = (cols - pupil.cx) / pupil.radius
    y = (pupil.cy - rows) / pupil.radius
    flat = (rows * aperture.shape[1] + cols).astype(np.intp)
    excluded = 0
    if user_pupil:
        inside = x * x + y * y <= 1.0 + _PUPIL_TOLERANCE
        excluded = int(inside.size - np.count_nonzero(inside))
        if excluded:
            logger.warning("%d valid pixels lie outside the given pupil and are left out", excluded)
            flat, x, y = flat[inside], x[inside], y[inside]
    if flat.size == 0:
        raise ValueError(f"pupil: no valid pixel of the aperture lies inside {pupil}")
    return _Samples(flat, x, y, excluded)


def _check_arguments(method: str, modes: int, ordering: str, dtype: np.dtype) -> None:
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {', '.join(_METHODS)}, got {method!r}")
    if isinstance(modes, bool) or not isinstance(modes, (int, np.integer)) or modes < 1:
        raise ValueError(f"modes: expected a positive integer, got {modes!r}")
    if ordering not in _ORDERINGS:
        raise ValueError(f"ordering: expected one of {', '.join(_ORDERINGS)}, got {ordering!r}")
    if dtype not in _DTYPES:
        raise ValueError(f"dtype: expected float32 or float64, got {dtype}")


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
) -> Fitter:
    """Precompute everything needed to refit frames on one aperture.

    Parameters
    ----------
    aperture_or_mask : Aperture or ndarray of shape (rows, cols)
        The aperture, or a mask (non-zero = valid) to build it from.
    method : {"circle", "qr"}
        ``circle``: Zernike polynomials over the pupil circle. ``qr``: the same modes
        orthonormalised over the samples; ``FitResult.circle_coefficients`` converts back.
    modes : int
        Number of modes: the first ``modes`` terms of ``ordering`` (36 Noll terms reach n = 7;
        231 reach n = 20).
    ordering : {"noll", "ansi", "fringe"}
        Index convention (see :mod:`wavestack.pipeline.zernike_index`).
    pupil : Pupil or (cx, cy, r), optional
        The unit disk in pixels, cx a column and cy a row coordinate. Default: the aperture's
        minimum enclosing circle through the outermost valid pixel centres. Valid pixels outside
        a given pupil are left out of the fit (counted in ``diagnostics``).
    dtype : {numpy.float32, numpy.float64}
        Type of the stored operator and the per-frame product; the factorisations are float64.
    normalisation : {"rms", "edge"}, optional
        Output normalisation of circle coefficients; default: the ordering's own (unit RMS for
        Noll and ANSI, unit edge value for Fringe).
    remove : {"ptt", "pttp"}, optional
        Fit and remove piston and tilt (and power) in physical coordinates before the fit; they
        are reported in ``FitResult.removed``.

    Returns
    -------
    Fitter

    Raises
    ------
    ValueError
        For an invalid argument (the message names it), an empty aperture, or a pupil that
        misses the aperture.
    IllConditionedBasis
        If the modes are linearly dependent on the samples.
    """
    started = time.perf_counter()
    dtype = np.dtype(dtype)
    _check_arguments(method, modes, ordering, dtype)
    normalisation = normalisation or default_normalisation(ordering)
    if normalisation not in ("rms", "edge"):
        raise ValueError(f"normalisation: expected 'rms' or 'edge', got {normalisation!r}")
    removal_names = physical_term_names(remove) if remove is not None else ()

    aperture = _aperture_of(aperture_or_mask)
    resolved_pupil = _pupil_of(aperture, pupil)
    samples = _samples_of(aperture, resolved_pupil, user_pupil=pupil is not None)
    timings = {"aperture": time.perf_counter() - started}

    mode_pairs = mode_list(ordering, int(modes))
    scale = np.array(
        [normalisation_factor(n, m, "rms") / normalisation_factor(n, m, normalisation)
         for n, m in mode_pairs]
    )
    spec = _METHODS[method]
    tick = time.perf_counter()
    columns = spec.columns(samples, mode_pairs)
    timings["basis"] = time.perf_counter() - tick

    tick = time.perf_counter()
    orthonormal, triangular = _orthonormalise(columns, method)
    del columns
    kappa, gain = _factor_quality(triangular)
    to_basis = scale[:, None] * scipy.linalg.solve_triangular(
        triangular, np.eye(len(mode_pairs)), lower=False
    )  # orthonormal coefficients -> the basis' own coefficients, in the output normalisation
    removal_transform = None
    if removal_names:
        terms = physical_term_basis(samples.x, samples.y, remove)
        terms_orthonormal, terms_triangular = _orthonormalise(terms, f"remove={remove}")
        removal_transform = scipy.linalg.solve_triangular(
            terms_triangular, np.eye(len(removal_names)), lower=False
        )
        orthonormal = np.hstack([orthonormal, terms_orthonormal])
    operator = _stored_operator(orthonormal, dtype)
    equations = NormalEquations(
        orthonormal.T @ orthonormal, orthonormal.sum(axis=0), len(mode_pairs), samples.x.size
    )
    del orthonormal
    if spec.orthonormal_output:
        coefficient_transform, circle_transform = np.eye(len(mode_pairs)), to_basis
        from_coefficients = np.eye(len(mode_pairs))
        own_gram = normalised_gram(equations.gram[: len(mode_pairs), : len(mode_pairs)], samples.x.size)
        kappa, gain = gram_condition(own_gram), noise_gain(own_gram)
    else:
        coefficient_transform, circle_transform = to_basis, None
        from_coefficients = triangular / scale[None, :]
    timings["factorise"] = time.perf_counter() - tick
    timings["total"] = time.perf_counter() - started

    basis = FitBasis(
        method=method,
        ordering=ordering,
        normalisation="aperture-rms" if spec.orthonormal_output else normalisation,
        modes=tuple(mode_pairs),
        first_index=0 if ordering == "ansi" else 1,
        pupil=resolved_pupil,
    )
    diagnostics = FitterDiagnostics(
        method=method,
        topology=aperture.topology.value,
        valid_pixels=int(samples.x.size),
        excluded_outside_pupil=samples.excluded,
        gram_condition=kappa,
        noise_gain=gain,
        timings=timings,
    )
    logger.info(
        "built %s fitter: %d modes on %d samples, kappa(G)=%.3g, %.3f s",
        method, len(mode_pairs), samples.x.size, kappa, timings["total"],
    )
    return Fitter(
        aperture=aperture,
        flat_index=samples.flat_index,
        operator=operator,
        equations=equations,
        coefficient_transform=coefficient_transform,
        from_coefficients=from_coefficients,
        basis=basis,
        diagnostics=diagnostics,
        circle_transform=circle_transform,
        removal=remove,
        removal_transform=removal_transform,
    )
