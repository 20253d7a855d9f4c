"""Phase-shifting interferometry (PSI): the wrapped phase from N frames taken at N phase steps.

Sign convention (project-wide)
------------------------------
Frame ``k`` is modelled as

    I_k(x, y) = A(x, y) + B(x, y) cos(phi(x, y) + delta_k),

where ``delta_k`` are the reference phase steps. *Counter-clockwise* (``direction="ccw"``,
the default, and what the real data in ``/work/shared/data/psi-mirror-654nm`` use) means
``delta_k = +k * step``; *clockwise* (``"cw"``) means ``delta_k = -k * step``. Every function
here returns ``phi`` in radians, wrapped to (-pi, pi], referenced to the first frame
(``delta_0 = 0``). A positive ``phi`` is a positive wavefront: the wavefront in waves is
``phi / (2 pi)``. Writing ``C = B cos(phi)`` and ``S = B sin(phi)`` the model is linear,

    I_k = A + C cos(delta_k) - S sin(delta_k),

so every algorithm below ends by applying a (3, N) matrix of weights to the frames, giving
(A, C, S) per pixel, then ``phi = atan2(S, C)`` and ``B = hypot(C, S)``. That last step is one
pass over the frames in blocks that stay in cache (:func:`_demodulate`); the methods differ only
in how they obtain the steps and hence the weights.

The ``quality`` map of :class:`PhaseResult` is the fringe visibility ``B / A`` clipped to
[0, 1] (0 where ``A <= 0``): near 1 for clean, well-contrasted fringes, near 0 where there are
no fringes (outside the pupil, in a speckled halo, on a saturated or dark pixel).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .angles import wrap_angle

logger = logging.getLogger(__name__)

_BLOCK_PIXELS = 1 << 16  # pixels per block of the final demodulation: N frames + outputs stay in cache
_SAMPLE_PIXELS = 1 << 15  # at most this many pixels feed the step estimators (AIA, PCA)
_MIN_SAMPLE_PIXELS = 16  # fewer pixels than this cannot estimate steps reliably
_AUTO_MASK_FRACTION = 0.25  # AIA without a mask: keep pixels with B >= this x the 99th percentile of B
_RANK_TOLERANCE = 1e-4  # smallest accepted singular-value ratio of a design matrix
_METHODS = ("lsq", "four", "hariharan", "aia", "pca")
_DIRECTIONS = ("ccw", "cw")


@dataclass(frozen=True, eq=False)
class PhaseResult:
    """Wrapped phase and the fringe parameters recovered from a set of phase-shifted frames.

    All maps are read-only float64 arrays of shape (rows, cols).

    Attributes
    ----------
    phase : ndarray of float64, shape (rows, cols)
        Wrapped phase ``phi`` of the first frame, radians in (-pi, pi]; sign convention in the
        module docstring.
    modulation : ndarray of float64, shape (rows, cols)
        Fringe amplitude ``B``, in the intensity units of the frames.
    background : ndarray of float64, shape (rows, cols)
        Background ``A``, in the intensity units of the frames.
    quality : ndarray of float64, shape (rows, cols)
        Fringe visibility ``B / A`` clipped to [0, 1]; 0 where ``A <= 0``.
    steps : ndarray of float64, shape (N,)
        Phase steps ``delta_k`` used for the demodulation (estimated by ``aia`` and ``pca``),
        radians, ``delta_0 = 0``, unwrapped so consecutive steps differ by less than pi.
    method : str
        "four", "hariharan", "lsq", "aia" or "pca".
    iterations : int or None
        Iterations the AIA took; None for the direct methods.
    """

    phase: NDArray[np.float64]
    modulation: NDArray[np.float64]
    background: NDArray[np.float64]
    quality: NDArray[np.float64]
    steps: NDArray[np.float64]
    method: str
    iterations: int | None = None


# ----------------------------------------------------------------------------- validation


def _frame_stack(frames: ArrayLike | Sequence[ArrayLike]) -> NDArray:
    """The frames as one (N, rows, cols) real array (no copy when already one)."""
    if isinstance(frames, np.ndarray):
        stack = frames
    else:
        if isinstance(frames, (str, bytes)):
            raise ValueError("frames: expected an (N, rows, cols) array or a sequence of 2-D arrays")
        try:
            arrays = [np.asarray(frame) for frame in frames]  # type: ignore[union-attr]
        except TypeError:
            raise ValueError(
                "frames: expected an (N, rows, cols) array or a sequence of 2-D arrays, "
                f"got {type(frames).__name__}"
            ) from None
        if not arrays:
            raise ValueError("frames: expected at least one frame, got an empty sequence")
        for index, array in enumerate(arrays):
            if array.ndim != 2:
                raise ValueError(f"frames: expected 2-D frames, frame {index} has shape {array.shape}")
            if array.shape != arrays[0].shape:
                raise ValueError(
                    f"frames: expected frames of equal shape, frame 0 is {arrays[0].shape} "
                    f"and frame {index} is {array.shape}"
                )
        stack = np.stack(arrays)
    if stack.ndim != 3:
        raise ValueError(f"frames: expected an (N, rows, cols) array, got shape {stack.shape}")
    if 0 in stack.shape:
        raise ValueError(f"frames: expected non-empty frames, got shape {stack.shape}")
    kind = stack.dtype.kind
    if kind not in "iuf":
        raise ValueError(f"frames: expected real numbers (integer or float), got dtype {stack.dtype}")
    return stack


def _require_count(stack: NDArray, allowed: str, ok: bool) -> None:
    if not ok:
        raise ValueError(f"frames: expected {allowed} frames, got {stack.shape[0]}")


def _check_direction(direction: str) -> str:
    if direction not in _DIRECTIONS:
        raise ValueError(f"direction: expected 'ccw' or 'cw', got {direction!r}")
    return direction


def _steps_array(steps: ArrayLike, count: int, name: str) -> NDArray[np.float64]:
    """``steps`` as a finite float64 vector of length ``count``."""
    try:
        array = np.asarray(steps, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {count} phase steps in radians") from None
    if array.shape != (count,):
        raise ValueError(f"{name}: expected {count} phase steps (one per frame), got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite phase steps in radians")
    return array


def _nominal_steps(count: int, direction: str) -> NDArray[np.float64]:
    """Equal steps over one cycle, ``delta_k = +-2 pi k / N``."""
    sign = 1.0 if direction == "ccw" else -1.0
    return sign * 2.0 * np.pi * np.arange(count) / count


def _mask_array(mask: ArrayLike | None, shape: tuple[int, int]) -> NDArray[np.bool_] | None:
    if mask is None:
        return None
    array = np.asarray(mask)
    if array.dtype != np.bool_:
        raise ValueError(f"mask: expected a boolean array, got dtype {array.dtype}")
    if array.shape != shape:
        raise ValueError(f"mask: expected shape {shape} (that of a frame), got {array.shape}")
    if np.count_nonzero(array) < _MIN_SAMPLE_PIXELS:
        raise ValueError(f"mask: expected at least {_MIN_SAMPLE_PIXELS} true pixels")
    return array


def _work_dtype(dtype: np.dtype) -> type[np.floating]:
    """float32 where it holds the data exactly enough (<= 16-bit integers, float16/32), else float64."""
    if (dtype.kind in "iu" and dtype.itemsize <= 2) or (dtype.kind == "f" and dtype.itemsize <= 4):
        return np.float32
    return np.float64


# ----------------------------------------------------------------------------- demodulation core


def _lsq_weights(steps: NDArray[np.float64], name: str) -> NDArray[np.float64]:
    """(3, N) least-squares weights giving (A, C, S) from frames taken at ``steps``."""
    design = np.column_stack([np.ones_like(steps), np.cos(steps), -np.sin(steps)])
    singular = np.linalg.svd(design, compute_uv=False)
    if singular[-1] <= _RANK_TOLERANCE * singular[0]:
        raise ValueError(
            f"{name}: expected at least three distinct phase steps (modulo 2 pi); "
            f"got {np.round(np.degrees(steps), 3).tolist()} degrees"
        )
    return np.linalg.pinv(design)


def _apply(weights: NDArray[np.float64], values: NDArray[np.float64]) -> NDArray[np.float64]:
    """``weights @ values`` for a few rows of weights.

    Done by ``einsum`` rather than BLAS: these products are small, and a multi-threaded BLAS
    waking its threads for each of them costs milliseconds per call on a busy machine.
    """
    return np.einsum("kn,np->kp", weights, values)


def _readonly(array: NDArray) -> NDArray:
    array.flags.writeable = False
    return array


def _demodulate(
    stack: NDArray, weights: NDArray[np.float64], steps: NDArray[np.float64], method: str,
    iterations: int | None = None,
) -> PhaseResult:
    """Apply (3, N) weights giving (A, C, S) per pixel and build the :class:`PhaseResult`.

    Works block by block over the pixels so that the N input rows, the scratch buffers and the
    output slices of a block stay in cache; frames of integers up to 16 bits and float32 frames
    are processed in float32 (exact for the sums involved), others in float64. The four output
    maps share one allocation. Single-threaded (``einsum``, not BLAS: see :func:`_apply`).
    """
    count, rows, cols = stack.shape
    pixels = rows * cols
    flat = stack.reshape(count, pixels)
    work = _work_dtype(stack.dtype)
    w = np.ascontiguousarray(weights, dtype=work)
    check_finite = stack.dtype.kind == "f"
    maps = np.empty((4, pixels), dtype=np.float64)  # phase, modulation, background, quality
    size = min(_BLOCK_PIXELS, pixels)
    block = np.empty((count, size), dtype=work)
    fitted = np.empty((3, size), dtype=work)
    scratch = np.empty((2, size), dtype=work)
    for start in range(0, pixels, size):
        stop = min(start + size, pixels)
        used = stop - start
        values = block[:, :used]
        np.copyto(values, flat[:, start:stop], casting="unsafe")
        abc = fitted[:, :used]
        np.einsum("kn,np->kp", w, values, out=abc)
        if check_finite and not np.isfinite(abc).all():
            raise ValueError("frames: expected finite values, found NaN or infinity")
        a, c, s = abc
        s += 0.0  # -0.0 -> +0.0, so that atan2 gives +pi rather than -pi on the negative C axis
        phase, modulation, background, quality = maps[:, start:stop]
        np.arctan2(s, c, out=phase)
        # a float32 atan2 can round one ulp beyond +-pi: clamp, then send -pi to +pi
        np.clip(phase, -np.pi, np.pi, out=phase)
        np.copyto(phase, np.pi, where=phase == -np.pi)
        squared, other = scratch[:, :used]
        np.multiply(c, c, out=squared)
        np.multiply(s, s, out=other)
        squared += other
        np.sqrt(squared, out=modulation)
        background[...] = a
        quality.fill(0.0)
        np.divide(modulation, background, out=quality, where=background > 0)
        np.clip(quality, 0.0, 1.0, out=quality)
    maps = maps.reshape(4, rows, cols)
    maps.flags.writeable = False
    return PhaseResult(
        phase=maps[0],
        modulation=maps[1],
        background=maps[2],
        quality=maps[3],
        steps=_readonly(np.asarray(steps, dtype=np.float64).copy()),
        method=method,
        iterations=iterations,
    )


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


# ----------------------------------------------------------------------------- fixed-step formulas


def four_step(frames: ArrayLike | Sequence[ArrayLike]) -> PhaseResult:
    """Four-bucket PSI with steps 0, pi/2, pi, 3 pi/2 (counter-clockwise).

    ``phi = atan2(I_3 - I_1, I_0 - I_2)``, ``B = hypot(I_3 - I_1, I_0 - I_2) / 2`` and
    ``A = (I_0 + I_1 + I_2 + I_3) / 4``. Exact for the model of the module docstring; a step
    error gives a ripple at twice the fringe frequency. For clockwise data use
    ``phase_from_frames(frames, "four", direction="cw")``.

    Parameters
    ----------
    frames : array_like, shape (4, rows, cols), or a sequence of 4 arrays of shape (rows, cols)
        Intensity frames, any real dtype (uint8 frames are processed in float32).

    Returns
    -------
    PhaseResult
        ``steps`` = (0, pi/2, pi, 3 pi/2), ``method`` = "four".

    Raises
    ------
    ValueError
        If ``frames`` is not 4 equal-shape 2-D real frames, or holds NaN or infinity.

    References
    ----------
    J. E. Greivenkamp and J. H. Bruning, "Phase shifting interferometry", in D. Malacara (ed.),
    *Optical Shop Testing*, 2nd ed., Wiley (1992), ch. 14: the four-step algorithm
    ``tan(phi) = (I_4 - I_2) / (I_1 - I_3)`` (frames numbered from 1), which is the N = 4 case
    of the least-squares solution of :func:`least_squares_psi`.
    """
    stack = _frame_stack(frames)
    _require_count(stack, "exactly 4", stack.shape[0] == 4)
    weights = np.array([
        [0.25, 0.25, 0.25, 0.25],  # A
        [0.5, 0.0, -0.5, 0.0],  # C = B cos(phi) = (I0 - I2) / 2
        [0.0, -0.5, 0.0, 0.5],  # S = B sin(phi) = (I3 - I1) / 2
    ])
    return _demodulate(stack, weights, np.arange(4) * (np.pi / 2), "four")


def hariharan_five_step(frames: ArrayLike | Sequence[ArrayLike]) -> PhaseResult:
    """Five-bucket PSI of Hariharan, Oreb and Eiju: steps of pi/2, insensitive to step scale error.

    The paper centres the steps on the middle frame (-pi ... pi); with the project convention
    ``delta_0 = 0`` the steps are 0, pi/2, pi, 3 pi/2, 2 pi and the phase of the first frame is
    ``phi = atan2(2 (I_3 - I_1), I_0 - 2 I_2 + I_4)`` (the paper's
    ``tan(phi_c) = 2 (I_2 - I_4) / (2 I_3 - I_5 - I_1)``, 1-based, with ``phi_c = phi + pi``).
    A linear step error ``pi/2 (1 + e)`` changes the phase only at order ``e**2``.
    ``B = hypot(2 (I_3 - I_1), I_0 - 2 I_2 + I_4) / 4`` and
    ``A = (I_0 + 2 I_1 + 2 I_2 + 2 I_3 + I_4) / 8``. For clockwise data use
    ``phase_from_frames(frames, "hariharan", direction="cw")``.

    Parameters
    ----------
    frames : array_like, shape (5, rows, cols), or a sequence of 5 arrays of shape (rows, cols)
        Intensity frames, any real dtype.

    Returns
    -------
    PhaseResult
        ``steps`` = (0, pi/2, pi, 3 pi/2, 2 pi), ``method`` = "hariharan".

    Raises
    ------
    ValueError
        If ``frames`` is not 5 equal-shape 2-D real frames, or holds NaN or infinity.

    References
    ----------
    P. Hariharan, B. F. Oreb and T. Eiju, "Digital phase-shifting interferometry: a simple
    error-compensating phase calculation algorithm", Appl. Opt. 26(13), 2504-2506 (1987): the
    five-frame formula ``tan(phi) = 2 (I_2 - I_4) / (2 I_3 - I_5 - I_1)`` and its insensitivity
    to the step error to first order.
    """
    stack = _frame_stack(frames)
    _require_count(stack, "exactly 5", stack.shape[0] == 5)
    weights = np.array([
        [0.125, 0.25, 0.25, 0.25, 0.125],  # A
        [0.25, 0.0, -0.5, 0.0, 0.25],  # C = (I0 - 2 I2 + I4) / 4
        [0.0, -0.5, 0.0, 0.5, 0.0],  # S = (I3 - I1) / 2
    ])
    return _demodulate(stack, weights, np.arange(5) * (np.pi / 2), "hariharan")


def least_squares_psi(frames: ArrayLike | Sequence[ArrayLike], steps: ArrayLike) -> PhaseResult:
    """General N-bucket PSI with known, arbitrary phase steps (least squares).

    Fits ``I_k = A + C cos(delta_k) - S sin(delta_k)`` per pixel; the (3, N) pseudo-inverse of
    the design matrix is computed once, so the per-pixel work is three weighted sums.

    Parameters
    ----------
    frames : array_like, shape (N, rows, cols), or a sequence of N arrays of shape (rows, cols)
        Intensity frames, N >= 3, any real dtype.
    steps : array_like, shape (N,)
        Phase step ``delta_k`` of each frame, radians, in the sign convention of the module
        (positive for counter-clockwise). Taken relative to ``steps[0]``: the returned phase is
        that of frame 0.

    Returns
    -------
    PhaseResult
        ``steps`` = the given steps minus ``steps[0]``, ``method`` = "lsq".

    Raises
    ------
    ValueError
        If ``frames`` has fewer than 3 frames, unequal shapes or non-finite values, or
        ``steps`` has the wrong length, non-finite values, or fewer than three distinct steps
        modulo 2 pi.

    References
    ----------
    J. E. Greivenkamp, "Generalized data reduction for heterodyne interferometry",
    Opt. Eng. 23(4), 350-352 (1984): the least-squares fit of ``a0 + a1 cos(delta_k) +
    b1 sin(delta_k)`` to the N samples, solved by the normal equations (here by the pseudo-inverse
    of the design matrix, with ``a1 = C`` and ``b1 = -S``).
    """
    stack = _frame_stack(frames)
    _require_count(stack, "at least 3", stack.shape[0] >= 3)
    delta = _steps_array(steps, stack.shape[0], "steps")
    delta = delta - delta[0]
    return _demodulate(stack, _lsq_weights(delta, "steps"), delta, "lsq")


# ----------------------------------------------------------------------------- step estimators


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
    if not (isinstance(tolerance, Real) and not isinstance(tolerance, bool) and math.isfinite(tolerance)
            and tolerance > 0):
        raise ValueError(f"tolerance: expected a positive number of radians, got {tolerance!r}")
    if (isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer))
            or max_iterations < 1):
        raise ValueError(f"max_iterations: expected an integer >= 1, got {max_iterations!r}")
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


# ----------------------------------------------------------------------------- dispatcher


def _reversed(result: PhaseResult) -> PhaseResult:
    """The same fringes read with the opposite step direction: phase and steps negated."""
    phase = -result.phase
    phase[phase == -np.pi] = np.pi
    return PhaseResult(
        phase=_readonly(phase),
        modulation=result.modulation,
        background=result.background,
        quality=result.quality,
        steps=_readonly(-result.steps + 0.0),
        method=result.method,
        iterations=result.iterations,
    )


def phase_from_frames(
    frames: ArrayLike | Sequence[ArrayLike],
    method: str = "lsq",
    steps: ArrayLike | None = None,
    direction: str = "ccw",
) -> PhaseResult:
    """Wrapped phase from phase-shifted frames by the named method.

    Parameters
    ----------
    frames : array_like, shape (N, rows, cols), or a sequence of N arrays of shape (rows, cols)
        Intensity frames, any real dtype.
    method : {"lsq", "four", "hariharan", "aia", "pca"}
        :func:`least_squares_psi`, :func:`four_step`, :func:`hariharan_five_step`,
        :func:`advanced_iterative_psi` or :func:`pca_psi`.
    steps : array_like, shape (N,), optional
        Step magnitudes in radians, counted in the sense of ``direction`` (e.g. ``2 pi k / 6``
        for six counter-clockwise or clockwise frames). "lsq": the known steps (default equal
        steps over one cycle); "aia": the initial steps; "four", "hariharan", "pca": must be None.
    direction : {"ccw", "cw"}
        "ccw": ``delta_k = +steps[k]``; "cw": ``delta_k = -steps[k]``. The returned ``steps``
        are the signed ``delta_k``.

    Returns
    -------
    PhaseResult
        As returned by the chosen method, in the project sign convention.

    Raises
    ------
    ValueError
        If ``method`` or ``direction`` is unknown, ``steps`` is given to a method that fixes or
        estimates them itself, or the chosen method rejects its input.

    References
    ----------
    See the individual methods.
    """
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {', '.join(_METHODS)}, got {method!r}")
    _check_direction(direction)
    if method in ("four", "hariharan", "pca") and steps is not None:
        raise ValueError(f"steps: method {method!r} fixes or estimates the steps itself; expected None")
    if method == "four":
        result = four_step(frames)
        return result if direction == "ccw" else _reversed(result)
    if method == "hariharan":
        result = hariharan_five_step(frames)
        return result if direction == "ccw" else _reversed(result)
    if method == "pca":
        return pca_psi(frames, direction=direction)
    sign = 1.0 if direction == "ccw" else -1.0
    stack = _frame_stack(frames)
    _require_count(stack, "at least 3", stack.shape[0] >= 3)
    given = None if steps is None else sign * _steps_array(steps, stack.shape[0], "steps")
    if method == "aia":
        return advanced_iterative_psi(stack, given, direction=direction)
    return least_squares_psi(stack, _nominal_steps(stack.shape[0], direction) if given is None else given)
