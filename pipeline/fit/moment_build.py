"""Building the moment refit of a polynomial basis: strips, coefficients, orthonormal columns.

The work done once per aperture, with nothing of size N x M (N fitted pixels, M modes):

1. the fitted pixels as a mask (the aperture's or the given fit mask, less the pixels outside a
   user-given pupil), found in row blocks;
2. strips of that mask, each cut at the columns where it has no fitted pixel (the two sides of
   a central hole become two boxes, so no box spans the hole, where annular terms of high degree
   grow fast), and each box's Legendre coefficients of the basis and physical-term columns
   (:mod:`wavestack.pipeline.fit.legendre_moments`), with the strip count doubled until the
   coefficients' amplification is at most ``MAX_AMPLIFICATION``;
3. the Gram matrices from moments of each strip's mask, and CholeskyQR2 done on the
   coefficients (``T_Q = R^-T T_H``, twice), as :func:`~wavestack.pipeline.fit.orthonormal.orthonormalise`
   does on the pixel values: the columns come out orthonormal (unit RMS) on the fitted pixels.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from ..aperture import Aperture
from .legendre_moments import (
    MAX_AMPLIFICATION,
    ColumnFunction,
    MaskMoments,
    Strip,
    amplification,
    column_coefficients,
    gram_of,
    strip_moments,
    strips_of,
)
from ..zernike import annular_zernike_basis, zernike_basis
from .coefficient_maps import coefficient_maps
from .fitter import Fitter
from .moment_projection import MomentProjection, MomentState
from .normal_equations import NormalEquations
from .orthonormal import check_condition, cholesky_factor, factor_quality
from .physical_terms import physical_term_basis
from .results import FitBasis, FitterDiagnostics, Pupil

if TYPE_CHECKING:  # only for annotations (the request module loads the mapped methods)
    from .request import BuildRequest


logger = logging.getLogger(__name__)

# Same tolerance as the operator path's samples (:mod:`wavestack.pipeline.fit.sampling`).
_PUPIL_TOLERANCE = 1e-9
_MASK_BLOCK_ROWS = 256
# Strip counts tried, doubling: past 64 strips the coefficients outweigh the frame they replace,
# and strips thinner than 4 rows gain nothing.
_MAX_STRIPS = 64
_MIN_STRIP_ROWS = 4


@dataclass(frozen=True)
class MomentFactors:
    """A moment build: the state of the projection and the triangular factors.

    Attributes
    ----------
    state : MomentState
    triangular : ndarray, shape (M, M)
        R of the basis (``H = Q R``, ``Q^T Q = N I``).
    removal_triangular : ndarray, shape (k, k) or None
        R of the physical terms.
    gram : ndarray, shape (M + k, M + k)
        ``A^T A`` of the orthonormalised columns.
    column_sums : ndarray, shape (M + k,)
    amplification : float
        The largest coefficient row sum of the stored columns times sqrt(kappa(G)) of the basis:
        the factor by which float64 rounding of the moments reaches the reported coefficients
        (see :mod:`wavestack.pipeline.fit.legendre_moments`).
    strips : int
    basis_seconds : float
        Time spent on the columns' coefficients (the rest is the factorisation).
    """

    state: MomentState
    triangular: NDArray[np.float64]
    removal_triangular: NDArray[np.float64] | None
    gram: NDArray[np.float64]
    column_sums: NDArray[np.float64]
    amplification: float
    strips: int
    basis_seconds: float = 0.0


def fitted_mask(
    aperture: Aperture, pupil: Pupil, user_pupil: bool, fit_mask: NDArray[np.bool_] | None
) -> tuple[NDArray[np.bool_], int]:
    """The fitted pixels (as :func:`~wavestack.pipeline.fit.sampling.samples_of`) and how many
    valid pixels a user-given pupil left out; computed in row blocks, no per-pixel float arrays.

    Raises
    ------
    ValueError
        If no pixel is left to fit.
    """
    mask = np.array(aperture.mask if fit_mask is None else fit_mask, dtype=bool)
    excluded = 0
    if user_pupil:
        cols = (np.arange(mask.shape[1]) - pupil.cx) / pupil.radius
        for start in range(0, mask.shape[0], _MASK_BLOCK_ROWS):
            rows = (pupil.cy - np.arange(start, min(start + _MASK_BLOCK_ROWS, mask.shape[0]))) / pupil.radius
            inside = rows[:, None] ** 2 + cols[None, :] ** 2 <= 1.0 + _PUPIL_TOLERANCE
            block = mask[start:start + rows.size]
            excluded += int(np.count_nonzero(block & ~inside))
            block &= inside
        if excluded:
            logger.warning("%d valid pixels lie outside the given pupil and are left out", excluded)
    if not mask.any():
        raise ValueError(f"pupil: no valid pixel of the aperture lies inside {pupil}")
    return mask, excluded


def boxes_of(mask: NDArray[np.bool_], count: int) -> list[Strip]:
    """:func:`~wavestack.pipeline.fit.legendre_moments.strips_of`, each strip cut at the columns
    where it has no fitted pixel: disjoint boxes, none spanning a gap of the mask.

    Measured on a 400 px annulus at degree 20 with 64 strips, the coefficients' amplification
    drops from 1.3e5 to 170 at obscuration 0.5, and from 1.1e13 to 2.1e4 at 0.9 (boxes spanning
    the hole reach far outside the annulus, where annular terms grow like a Chebyshev polynomial
    outside its interval). A mask without such gaps (a disk) keeps its strips.
    """
    boxes = []
    for strip in strips_of(mask, count):
        used = np.flatnonzero(mask[strip.row0:strip.row1, strip.col0:strip.col1].any(axis=0))
        cuts = np.flatnonzero(np.diff(used) > 1)
        starts, stops = np.r_[used[0], used[cuts + 1]], np.r_[used[cuts], used[-1]] + 1
        boxes.extend(Strip(strip.row0, strip.row1, strip.col0 + int(a), strip.col0 + int(b))
                     for a, b in zip(starts, stops))
    return boxes


def _coefficients(columns: ColumnFunction, strips: list, pupil: Pupil, degree: int) -> list[NDArray]:
    def to_unit(rows: NDArray, cols: NDArray) -> tuple[NDArray, NDArray]:
        return (cols - pupil.cx) / pupil.radius, (pupil.cy - rows) / pupil.radius

    return column_coefficients(columns, strips, to_unit, degree)


def _orthonormal(
    coefficients: list[NDArray], moments: list[MaskMoments], n: int, what: str
) -> tuple[list[NDArray], NDArray[np.float64]]:
    """CholeskyQR2 on coefficients: ``T_Q = R^-T T`` with ``Q^T Q = N I`` over the pixels."""
    size = coefficients[0].shape[0]
    r_total = np.eye(size)
    for _ in range(2):
        gram, _ = gram_of(coefficients, moments)
        r = cholesky_factor(gram / n, what, n)
        inverse = scipy.linalg.solve_triangular(r, np.eye(size), lower=False)
        coefficients = [inverse.T @ t for t in coefficients]
        r_total = r @ r_total
    check_condition(r_total, what, n)
    return coefficients, r_total


def build_moments(
    mask: NDArray[np.bool_],
    pupil: Pupil,
    basis: ColumnFunction,
    degree: int,
    what: str,
    terms: ColumnFunction | None = None,
) -> MomentFactors | None:
    """Moment factors of polynomial columns on the pixels of ``mask``, or None when even the
    finest strips leave the effective amplification above ``MAX_AMPLIFICATION`` (use the
    operator then: an ill-conditioned basis, kappa(G) above ~1e8, always does).

    Parameters
    ----------
    mask : ndarray of bool, shape (rows, cols)
        The fitted pixels.
    pupil : Pupil
        The unit disk of the columns' coordinates.
    basis : callable
        ``basis(x, y)`` gives the M basis columns (unit RMS over the disk) at unit-disk points.
    degree : int
        Largest total degree of the basis and the physical terms.
    what : str
        Name of the basis, for error messages.
    terms : callable, optional
        The physical-term columns removed before the fit.

    Raises
    ------
    IllConditionedBasis
        As :func:`~wavestack.pipeline.fit.orthonormal.orthonormalise`.
    """
    n = int(np.count_nonzero(mask))
    rows = int(np.count_nonzero(mask.any(axis=1)))
    most = max(1, min(_MAX_STRIPS, rows // _MIN_STRIP_ROWS))
    started = time.perf_counter()
    count = 1  # the fewest strips whose basis coefficients alone pass (cheap: no Gram matrix)
    strips = boxes_of(mask, count)
    coefficients = _coefficients(basis, strips, pupil, degree)
    while count < most and max(amplification(t) for t in coefficients) > MAX_AMPLIFICATION:
        count *= 2
        strips = boxes_of(mask, min(count, most))
        coefficients = _coefficients(basis, strips, pupil, degree)
    seconds = time.perf_counter() - started
    while True:
        factors = _factors(mask, strips, pupil, coefficients, degree, what, terms, n)
        logger.debug("moments: %d strips, effective amplification %.3g", factors.strips, factors.amplification)
        if factors.amplification <= MAX_AMPLIFICATION:
            return dataclasses.replace(factors, basis_seconds=seconds)
        if count >= most:
            return None
        count *= 2
        strips = boxes_of(mask, min(count, most))
        coefficients = _coefficients(basis, strips, pupil, degree)


def _factors(mask: NDArray[np.bool_], strips: list, pupil: Pupil, coefficients: list[NDArray], degree: int,
             what: str, terms: ColumnFunction | None, n: int) -> MomentFactors:
    """The factors on these strips, from the basis' coefficients on them."""
    moments = strip_moments(mask, strips, degree)
    columns, triangular = _orthonormal(coefficients, moments, n, what)
    removal_triangular = None
    if terms is not None:
        extra, removal_triangular = _orthonormal(_coefficients(terms, strips, pupil, degree), moments, n,
                                                 "physical terms")
        columns = [np.vstack([c, e]) for c, e in zip(columns, extra)]
    gram, sums = gram_of(columns, moments)
    transform = np.hstack(columns)
    state = MomentState(mask, np.array([[s.row0, s.row1, s.col0, s.col1] for s in strips], dtype=np.int64),
                        degree, transform)
    kappa, _ = factor_quality(triangular)  # the map to the basis' own coefficients adds sqrt(kappa(G))
    effective = max(amplification(c) for c in columns) * float(np.sqrt(kappa))
    return MomentFactors(state, triangular, removal_triangular, gram, sums, effective, len(strips))


def build_moment_fitter(aperture: Aperture, request: BuildRequest, basis: FitBasis, scale: NDArray[np.float64],
                        started: float) -> Fitter | None:
    """A fitter that refits by separable moments, or None where they would lose precision.

    Parameters
    ----------
    aperture : Aperture
    request : BuildRequest
        Of a polynomial method (``circle``, ``qr``, ``annulus``).
    basis : FitBasis
        What the coefficients mean (modes, ordering, normalisation, pupil, and for ``annulus``
        the obscuration ratio of its annular Zernike columns).
    scale : ndarray, shape (M,)
        Each mode's factor from unit RMS to the output normalisation.
    started : float
        ``time.perf_counter()`` at the start of the build (for the timings).

    Raises
    ------
    ValueError
        If no pixel is left to fit.
    IllConditionedBasis
        If the modes are linearly dependent on the fitted pixels, or kappa(G) exceeds 2**52.
    """
    pupil, modes = basis.pupil, list(basis.modes)
    mask, excluded = fitted_mask(aperture, pupil, request.user_pupil, request.fit_mask)
    timings = {"aperture": time.perf_counter() - started}
    tick = time.perf_counter()
    degree = max(max(n for n, _ in modes), 0 if request.remove is None else (1 if request.remove == "ptt" else 2))
    terms = None if request.remove is None else partial(_physical_terms, request.remove)
    columns = partial(_zernike_columns, modes)
    if basis.annular_obscuration is not None:
        columns = partial(annular_zernike_basis, modes, obscuration=basis.annular_obscuration)
    factors = build_moments(mask, pupil, columns, degree, request.method, terms)
    if factors is not None:
        timings["basis"] = factors.basis_seconds
    timings["factorise"] = time.perf_counter() - tick - timings.get("basis", 0.0)
    if factors is None:
        logger.info("moments would amplify rounding above %g on this aperture; using the operator",
                    MAX_AMPLIFICATION)
        return None
    n = factors.state.mask.sum()
    equations = NormalEquations(factors.gram, factors.column_sums, len(modes), int(n))
    maps = coefficient_maps(request.method, scale, factors.triangular, factors.gram, int(n))
    removal_transform = None
    if factors.removal_triangular is not None:
        removal_transform = scipy.linalg.solve_triangular(
            factors.removal_triangular, np.eye(factors.removal_triangular.shape[0]), lower=False)
    timings["total"] = time.perf_counter() - started
    diagnostics = FitterDiagnostics(
        method=request.method, topology=aperture.topology.value, valid_pixels=int(n),
        excluded_outside_pupil=excluded, gram_condition=maps.kappa, noise_gain=maps.gain, timings=timings,
        refit="moments", moment_strips=factors.strips, moment_amplification=factors.amplification,
    )
    logger.info("built %s fitter (moments, %d strips): %d modes on %d samples, kappa(G)=%.3g, %.3f s",
                request.method, factors.strips, len(modes), n, maps.kappa, timings["total"])
    return Fitter(
        aperture=aperture, projection=MomentProjection(factors.state), equations=equations,
        coefficient_transform=maps.coefficient_transform, from_coefficients=maps.from_coefficients,
        basis=basis, diagnostics=diagnostics, dtype=request.dtype,
        circle_transform=maps.circle_transform, removal=request.remove, removal_transform=removal_transform,
    )


def _zernike_columns(modes: list[tuple[int, int]], x: NDArray, y: NDArray) -> NDArray:
    return zernike_basis(modes, x, y, normalisation="rms")


def _physical_terms(remove: str, x: NDArray, y: NDArray) -> NDArray:
    return physical_term_basis(x, y, remove)
