"""PSI entry points: :func:`phase_from_frames`, the fixed-step formulas and least squares.

The sign convention, the quality map and the fast path are described in
:mod:`wavestack.pipeline.phase.psi`; "the module docstring" below means that one.
"""

from __future__ import annotations

from collections.abc import Sequence

from numpy.typing import ArrayLike

from .demodulation import _demodulate, _lsq_weights, PhaseResult
from .estimated_steps import advanced_iterative_psi, pca_psi
from .fast import _FOUR, _HARIHARAN, _fixed_step
from .inputs import _check_direction, _frame_stack, _nominal_steps, _require_count, _steps_array

__all__ = [
    "PhaseResult",
    "advanced_iterative_psi",
    "four_step",
    "hariharan_five_step",
    "least_squares_psi",
    "pca_psi",
    "phase_from_frames",
]

_METHODS = ("lsq", "four", "hariharan", "aia", "pca")


# ----------------------------------------------------------------------------- direct methods (known steps)


def four_step(frames: ArrayLike | Sequence[ArrayLike]) -> PhaseResult:
    """Four-bucket PSI with steps 0, pi/2, pi, 3 pi/2 (counter-clockwise).

    ``phi = atan2(I_3 - I_1, I_0 - I_2)``, ``B = hypot(I_3 - I_1, I_0 - I_2) / 2`` and
    ``A = (I_0 + I_1 + I_2 + I_3) / 4``. Exact for the model of the module docstring; a step
    error gives a ripple at twice the fringe frequency. For clockwise data use
    ``phase_from_frames(frames, "four", direction="cw")``.

    Parameters
    ----------
    frames : array_like, shape (4, rows, cols), or a sequence of 4 arrays of shape (rows, cols)
        Intensity frames, any real dtype. Integers of up to 16 bits and float32 take the fast
        float32 path (module docstring); other dtypes are processed in float64.

    Returns
    -------
    PhaseResult
        ``steps`` = (0, pi/2, pi, 3 pi/2), ``method`` = "four". Float32 maps on the fast path
        (``background`` and ``quality`` computed on first access), float64 otherwise.

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
    return _fixed_step(frames, _FOUR, "ccw")


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
        Intensity frames, any real dtype. Integers of up to 16 bits and float32 take the fast
        float32 path (module docstring); other dtypes are processed in float64.

    Returns
    -------
    PhaseResult
        ``steps`` = (0, pi/2, pi, 3 pi/2, 2 pi), ``method`` = "hariharan". Float32 maps on the
        fast path (``background`` and ``quality`` computed on first access), float64 otherwise.

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
    return _fixed_step(frames, _HARIHARAN, "ccw")


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


# ----------------------------------------------------------------------------- dispatcher


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

    Examples
    --------
    Four frames ``1 + 0.5 cos(phi + k pi / 2)`` give back ``phi``:

    >>> import numpy as np
    >>> phi = np.linspace(-3.0, 3.0, 64).reshape(8, 8)
    >>> frames = [1.0 + 0.5 * np.cos(phi + k * np.pi / 2) for k in range(4)]
    >>> result = phase_from_frames(frames, method="four")
    >>> bool(np.allclose(result.phase, phi))
    True
    >>> np.round(phase_from_frames(frames).steps, 4)  # "lsq" with equal steps over one cycle
    array([0.    , 1.5708, 3.1416, 4.7124])
    """
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {', '.join(_METHODS)}, got {method!r}")
    _check_direction(direction)
    if method in ("four", "hariharan", "pca") and steps is not None:
        raise ValueError(f"steps: method {method!r} fixes or estimates the steps itself; expected None")
    if method == "four":
        return _fixed_step(frames, _FOUR, direction)
    if method == "hariharan":
        return _fixed_step(frames, _HARIHARAN, direction)
    if method == "pca":
        return pca_psi(frames, direction=direction)
    sign = 1.0 if direction == "ccw" else -1.0
    stack = _frame_stack(frames)
    _require_count(stack, "at least 3", stack.shape[0] >= 3)
    given = None if steps is None else sign * _steps_array(steps, stack.shape[0], "steps")
    if method == "aia":
        return advanced_iterative_psi(stack, given, direction=direction)
    return least_squares_psi(stack, _nominal_steps(stack.shape[0], direction) if given is None else given)
