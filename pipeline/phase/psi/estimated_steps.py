"""PSI with unknown phase steps: the advanced iterative algorithm (AIA) and PCA estimate them.

Both work on a subsample of the (masked) pixels, return the estimated steps referred to frame 0
and oriented by ``direction`` (:func:`_normalise_steps`), and demodulate the full frames once
with them by least squares (:func:`_demodulate`). Sign convention: module docstring of
:mod:`wavestack.pipeline.phase.psi`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._angles import wrap_angle
from ..._checks import int_at_least, is_finite_real
from .demodulation import _apply, _demodulate, _lsq_weights, PhaseResult
from .inputs import (
    _MIN_SAMPLE_PIXELS,
    _check_direction,
    _frame_stack,
    _mask_array,
    _nominal_steps,
    _require_count,
    _steps_array,
)

__all__ = ["advanced_iterative_psi", "pca_psi"]

# logged under the public module's name, as before the split, where callers configure it
logger = logging.getLogger(__name__.rpartition(".")[0] + ".psi")

_SAMPLE_PIXELS = 1 << 15  # at most this many pixels feed the step estimators (AIA, PCA)
_AUTO_MASK_FRACTION = 0.25  # AIA without a mask: keep pixels with B >= this x the 99th percentile of B


def _normalise_steps(steps: NDArray[np.float64], direction: str | None) -> NDArray[np.float64]:
    """Steps relative to the first (``delta_0 = 0``), unwrapped, oriented for ``direction``.

    The data fix the steps only up to a common offset and a common sign (``phi, delta`` and
    ``-phi, -delta`` give the same frames). The offset is removed by referring to frame 0; the
    sign is chosen so that the steps *increase* for ``"ccw"`` (decrease for ``"cw"``), judged by
    the sum of the wrapped consecutive differences, which equals ``delta_{N-1}`` after
    unwrapping. ``direction=None`` keeps the sign.
    """
    relative = np.unwrap(steps - steps[0])
    relative -= relative[0]
    if direction is not None:
        total = relative[-1]
        if (direction == "ccw" and total < 0) or (direction == "cw" and total > 0):
            relative = -relative
    return relative + 0.0  # no negative zeros


def _sample(stack: NDArray, mask: NDArray[np.bool_] | None) -> NDArray[np.float64]:
    """(N, M) float64 values of at most ``_SAMPLE_PIXELS`` pixels, evenly strided over the mask."""
    count = stack.shape[0]
    flat = stack.reshape(count, -1)
    if mask is None:
        stride = max(1, math.ceil(flat.shape[1] / _SAMPLE_PIXELS))
        return np.ascontiguousarray(flat[:, ::stride], dtype=np.float64)
    index = np.flatnonzero(mask)
    stride = max(1, math.ceil(index.size / _SAMPLE_PIXELS))
    return np.ascontiguousarray(flat[:, index[::stride]], dtype=np.float64)


def _well_modulated(sample: NDArray[np.float64], steps: NDArray[np.float64]) -> NDArray[np.float64]:
    """Columns of ``sample`` whose modulation is at least a fraction of the 99th percentile."""
    _, c, s = _apply(_lsq_weights(steps, "initial_steps"), sample)
    modulation = np.hypot(c, s)
    keep = modulation >= _AUTO_MASK_FRACTION * np.percentile(modulation, 99.0)
    if np.count_nonzero(keep) < _MIN_SAMPLE_PIXELS:
        return sample
    return np.ascontiguousarray(sample[:, keep])


def _fit_steps(sample: NDArray[np.float64], coefficients: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per-frame least squares of ``I_k - A = a_k + C cos(delta_k) - S sin(delta_k)`` over the pixels.

    Wang & Han's step estimation, with the per-pixel ``A``, ``C = B cos(phi)`` and
    ``S = B sin(phi)`` of the previous half-step as known quantities, so that a non-uniform
    background and modulation need no special treatment; ``a_k`` absorbs intensity drift.
    """
    background, c, s = coefficients
    pixels = c.size
    regressors = np.stack([np.ones_like(c), c, -s])  # (3, M)
    gram = np.einsum("ap,bp->ab", regressors, regressors)
    mean = gram[0, 1:] / pixels
    quadrature = np.linalg.eigvalsh(gram[1:, 1:] / pixels - np.outer(mean, mean))  # covariance of (C, -S)
    if not quadrature[-1] > 0 or quadrature[0] < 1e-6 * quadrature[-1]:
        raise ValueError(
            "frames: the phase does not vary enough over the pixels used to estimate the steps; "
            "expected at least about one fringe across the frame or mask"
        )
    # regressors (sample - background)' without forming the difference
    right = np.einsum("ap,kp->ak", regressors, sample)
    right -= np.einsum("ap,p->a", regressors, background)[:, None]
    solved = np.linalg.solve(gram, right)  # (3, N): a_k, cos(delta_k), sin(delta_k) (times a scale)
    return np.arctan2(solved[2], solved[1])


def advanced_iterative_psi(
    frames: ArrayLike | Sequence[ArrayLike],
    initial_steps: ArrayLike | None = None,
    *,
    tolerance: float = 1e-4,
    max_iterations: int = 50,
    mask: ArrayLike | None = None,
    direction: str = "ccw",
) -> PhaseResult:
    """Advanced iterative algorithm (AIA): phase and unknown phase steps by alternating least squares.

    Alternates (1) per-pixel least squares of (A, C, S) given the steps and (2) per-frame least
    squares of ``I_k - A = a_k + C cos(delta_k) - S sin(delta_k)`` for
    ``(a_k, cos delta_k, sin delta_k)`` given the per-pixel (A, C, S), on the masked pixels
    (subsampled to at most 32768). Step (2) subtracts the per-pixel background and regresses on
    ``C`` and ``S`` rather than on ``cos phi`` and ``sin phi`` as in the paper, which removes the
    paper's assumption of a spatially uniform background and modulation; the per-frame ``a_k``
    absorbs frame-to-frame intensity drift. Stops when no step moves by more than ``tolerance``
    in an iteration (convergence is linear, so the remaining step error is a few times
    ``tolerance``). The steps are then referred to frame 0 and oriented (increasing for "ccw",
    decreasing for "cw"), since the data cannot tell ``(phi, delta)`` from ``(-phi, -delta)``;
    the full frames are demodulated once with them. Needs a phase that varies over at least
    about one fringe across the pixels used.

    Parameters
    ----------
    frames : array_like, shape (N, rows, cols), or a sequence of N arrays of shape (rows, cols)
        Intensity frames, N >= 3, any real dtype.
    initial_steps : array_like, shape (N,), optional
        Starting steps in radians; default equal steps ``+-2 pi k / N`` over one cycle (use the
        nominal steps of the phase shifter when the frames span more or less than one cycle).
    tolerance : float
        Convergence threshold on the largest step change between iterations, radians (> 0).
    max_iterations : int
        Maximum number of iterations (>= 1); if reached, a warning is logged and the last
        estimate is used.
    mask : array_like of bool, shape (rows, cols), optional
        Pixels used to estimate the steps (the pupil). Default: the pixels whose modulation,
        computed with the initial steps, is at least 1/4 of its 99th percentile.
    direction : {"ccw", "cw"}
        Orientation of the returned steps: increasing ("ccw") or decreasing ("cw").

    Returns
    -------
    PhaseResult
        ``steps`` = the estimated steps (``delta_0 = 0``), ``method`` = "aia",
        ``iterations`` = number of iterations run.

    Raises
    ------
    ValueError
        If ``frames`` is invalid or has fewer than 3 frames, ``initial_steps`` has the wrong
        length or fewer than three distinct values, ``tolerance`` or ``max_iterations`` is out of
        range, ``mask`` has the wrong shape or dtype or fewer than 16 pixels, ``direction`` is
        unknown, or the phase does not vary enough over the pixels to estimate the steps.

    References
    ----------
    Z. Wang and B. Han, "Advanced iterative algorithm for phase extraction of randomly
    phase-shifted interferograms", Opt. Lett. 29(14), 1671-1673 (2004): the alternating
    per-pixel and per-frame least-squares estimates and the convergence criterion on the
    change of ``delta_k - delta_0`` between iterations.
    """
    stack = _frame_stack(frames)
    count = stack.shape[0]
    _require_count(stack, "at least 3", count >= 3)
    _check_direction(direction)
    if not (is_finite_real(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance: expected a positive number of radians, got {tolerance!r}")
    int_at_least(max_iterations, "max_iterations", 1, voice="expected")
    if initial_steps is None:
        steps = _nominal_steps(count, direction)
    else:
        steps = _steps_array(initial_steps, count, "initial_steps")
    steps = _normalise_steps(steps, None)
    _lsq_weights(steps, "initial_steps")
    checked_mask = _mask_array(mask, stack.shape[1:])
    sample = _sample(stack, checked_mask)
    if checked_mask is None:
        sample = _well_modulated(sample, steps)
    iterations = 0
    for iterations in range(1, int(max_iterations) + 1):
        coefficients = _apply(_lsq_weights(steps, "frames (estimated steps)"), sample)
        updated = _normalise_steps(_fit_steps(sample, coefficients), None)
        change = float(np.max(np.abs(wrap_angle(updated - steps))))
        steps = updated
        if change < tolerance:
            break
    else:
        logger.warning(
            "AIA did not converge in %d iterations (last step change %.3g rad > tolerance %.3g rad)",
            max_iterations, change, tolerance,
        )
    steps = _normalise_steps(steps, direction)
    return _demodulate(stack, _lsq_weights(steps, "frames (estimated steps)"), steps, "aia", iterations)


def _conic_normalised(
    quadratic: NDArray[np.float64], linear: NDArray[np.float64], constant: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Scale a conic ``p G p' + 2 p h + f = 0`` to ``|p T + m|^2 = 1``; return (T, m) or None.

    The scale makes the Schur complement ``f - h G^-1 h`` equal -1; the conic must then be an
    ellipse (``G`` positive definite). ``T`` is the Cholesky factor of ``G``, ``m = T^-1 h``.
    """
    try:
        schur = constant - linear @ np.linalg.solve(quadratic, linear)
    except np.linalg.LinAlgError:
        return None
    if not np.isfinite(schur) or schur == 0:
        return None
    scale = -1.0 / schur
    gram = scale * quadratic
    try:
        factor = np.linalg.cholesky(gram)
    except np.linalg.LinAlgError:
        return None
    centre = np.linalg.solve(factor, scale * linear)
    return factor, centre


def _steps_from_components(components: NDArray[np.float64]) -> NDArray[np.float64]:
    """Steps from the (N, 2) temporal principal components (rows ``u_k``).

    Noise-free, ``u_k T + m = (cos delta_k, -sin delta_k)`` for an unknown 2x2 ``T`` and
    2-vector ``m``: the ``u_k`` lie on an ellipse. With N >= 5 well-spread points an exact conic
    fit recovers ``T`` and ``m`` up to a rotation and a reflection (the common offset and sign
    of the steps). Otherwise (N = 3, 4, or repeated steps) Vargas et al.'s assumption that the
    two components are in quadrature with equal amplitude is used: a circle fit.
    """
    count = components.shape[0]
    points = components * math.sqrt(count)  # rows of an orthonormal basis: scale to ~1
    x, y = points[:, 0], points[:, 1]
    solution = None
    if count >= 5:
        design = np.column_stack([x * x, x * y, y * y, x, y, np.ones(count)])
        _, singular, vh = np.linalg.svd(design, full_matrices=True)
        if singular[4] > 1e-3 * singular[0]:
            a, b, c, d, e, f = vh[-1]
            solution = _conic_normalised(np.array([[a, b / 2], [b / 2, c]]), np.array([d / 2, e / 2]), f)
    if solution is None:
        design = np.column_stack([x * x + y * y, x, y, np.ones(count)])
        _, _, vh = np.linalg.svd(design, full_matrices=True)
        g, d, e, f = vh[-1]
        solution = _conic_normalised(np.array([[g, 0.0], [0.0, g]]), np.array([d / 2, e / 2]), f)
    if solution is None:
        raise ValueError("frames: the principal components do not trace an ellipse; cannot estimate the steps")
    factor, centre = solution
    unit = points @ factor + centre
    return np.arctan2(-unit[:, 1], unit[:, 0])


def pca_psi(
    frames: ArrayLike | Sequence[ArrayLike],
    *,
    mask: ArrayLike | None = None,
    direction: str = "ccw",
) -> PhaseResult:
    """PCA-based PSI: phase and unknown phase steps from the two main temporal principal components.

    Subtracts the temporal mean of each pixel, diagonalises the (N, N) Gram matrix of the
    (N x pixels) data (equivalent to the SVD, on the masked pixels, subsampled to at most 32768),
    and keeps the two main components: rank-2 fringes ``C cos(delta_k) - S sin(delta_k)``. Vargas
    et al. take the two principal components as the quadrature signals, which holds only for
    steps spread evenly over the circle. Here the steps are recovered exactly instead: the
    temporal components ``u_k`` lie on an ellipse, the affine image of the unit circle
    ``(cos delta_k, -sin delta_k)``, and an exact conic fit undoes that map (N >= 5; for N = 3, 4
    or repeated steps the ellipse is taken to be a circle, which is Vargas's assumption). The full
    frames are then demodulated with these steps by least squares, which for the estimated steps
    spans the same subspace as the mean plus the two components.

    PCA fixes the steps only up to a common offset and a common sign: they are referred to frame 0
    and oriented to increase ("ccw") or decrease ("cw"), judged by the sum of the wrapped
    consecutive step differences, so the phase follows the project convention.

    Parameters
    ----------
    frames : array_like, shape (N, rows, cols), or a sequence of N arrays of shape (rows, cols)
        Intensity frames, N >= 3, any real dtype.
    mask : array_like of bool, shape (rows, cols), optional
        Pixels used for the principal components (the pupil); default all pixels.
    direction : {"ccw", "cw"}
        Orientation of the returned steps: increasing ("ccw") or decreasing ("cw").

    Returns
    -------
    PhaseResult
        ``steps`` = the estimated steps (``delta_0 = 0``), ``method`` = "pca".

    Raises
    ------
    ValueError
        If ``frames`` is invalid or has fewer than 3 frames, ``mask`` has the wrong shape or dtype
        or fewer than 16 pixels, ``direction`` is unknown, or the frames do not hold two
        fringe components (no phase variation, or no phase shift).

    References
    ----------
    J. Vargas, J. A. Quiroga and T. Belenguer, "Phase-shifting interferometry based on principal
    component analysis", Opt. Lett. 36(8), 1326-1328 (2011): mean subtraction, the principal
    components of the N x pixels data matrix, and ``phi = atan(-PC2 / PC1)`` from the first two
    (replaced here by the ellipse-corrected steps and a least-squares demodulation).
    """
    stack = _frame_stack(frames)
    count = stack.shape[0]
    _require_count(stack, "at least 3", count >= 3)
    _check_direction(direction)
    checked_mask = _mask_array(mask, stack.shape[1:])
    sample = _sample(stack, checked_mask)
    centred = sample - sample.mean(axis=0)
    eigenvalues, eigenvectors = np.linalg.eigh(np.einsum("kp,lp->kl", centred, centred))
    if not eigenvalues[-1] > 0 or eigenvalues[-2] < 1e-9 * eigenvalues[-1]:
        raise ValueError(
            "frames: expected two fringe components (a phase that varies across the field and "
            "changes between frames); the data have fewer"
        )
    components = eigenvectors[:, [-1, -2]]
    steps = _normalise_steps(_steps_from_components(components), direction)
    return _demodulate(stack, _lsq_weights(steps, "frames (estimated steps)"), steps, "pca")
