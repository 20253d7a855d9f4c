"""The fixed-step formulas (four-step, Hariharan five-step) and their fast float32 path.

A :class:`_Formula` holds the integer coefficients of ``C`` and ``S`` and the weights of ``A``.
:func:`_fixed_step` validates the frames and, for frames of integers of up to 16 bits or float32,
forms ``C`` and ``S`` exactly in integers, block of rows by block of rows, and takes the float32
phase and modulation (:func:`_fixed_step_maps`); background and quality are computed on first
access. Other dtypes take the float64 weights path of :func:`_demodulate`. Accuracy and timing
are in the module docstring of :mod:`wavestack.pipeline.phase.psi`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .demodulation import _demodulate, _FringeMaps, _readonly, PhaseResult
from .inputs import _frame_stack, _require_count

_FAST_BLOCK_PIXELS = 1 << 17  # pixels per row block of the float32 fixed-step path (fewer Python calls)


@dataclass(frozen=True)
class _Formula:
    """A fixed-step formula with integer coefficients.

    ``C = scale * sum(c_terms)`` and ``S = scale * s_factor * sum(s_terms)`` are ``B cos(phi)``
    and ``B sin(phi)`` for the counter-clockwise steps ``delta_k = k * step``; a term is
    (frame index, +1 or -1). ``A = sum(a_weights[k] * I_k)``.
    """

    name: str
    count: int
    step: float
    c_terms: tuple[tuple[int, int], ...]
    s_terms: tuple[tuple[int, int], ...]
    s_factor: int
    scale: float
    a_weights: tuple[float, ...]

    def __post_init__(self) -> None:
        # the fast path sums C and S in place in the rows of their frames: they must not share one
        if {index for index, _ in self.c_terms} & {index for index, _ in self.s_terms}:
            raise ValueError(f"{self.name}: C and S must use disjoint frames")

    def weights(self, sign: float) -> NDArray[np.float64]:
        """(3, N) weights giving (A, C, S) for steps ``sign * k * step``."""
        weights = np.zeros((3, self.count))
        weights[0] = self.a_weights
        for index, term_sign in self.c_terms:
            weights[1, index] += term_sign * self.scale
        for index, term_sign in self.s_terms:
            weights[2, index] += sign * term_sign * self.s_factor * self.scale
        return weights


_FOUR = _Formula(
    "four", 4, np.pi / 2,
    c_terms=((0, 1), (2, -1)),  # C = (I0 - I2) / 2
    s_terms=((3, 1), (1, -1)), s_factor=1,  # S = (I3 - I1) / 2
    scale=0.5,
    a_weights=(0.25, 0.25, 0.25, 0.25),
)
_HARIHARAN = _Formula(
    "hariharan", 5, np.pi / 2,
    c_terms=((0, 1), (4, 1), (2, -1), (2, -1)),  # C = (I0 - 2 I2 + I4) / 4
    s_terms=((3, 1), (1, -1)), s_factor=2,  # S = 2 (I3 - I1) / 4
    scale=0.25,
    a_weights=(0.125, 0.25, 0.25, 0.25, 0.125),
)
_FAST_DTYPES = tuple(np.dtype(name) for name in ("uint8", "int8", "uint16", "int16", "float32"))
_FLOAT32_PI = np.float32(np.pi)


def _fixed_step(frames: ArrayLike | Sequence[ArrayLike], formula: _Formula, direction: str) -> PhaseResult:
    """Validate the frames and run ``formula``: the float32 fast path where the dtype allows it."""
    fresh = not isinstance(frames, np.ndarray)  # _frame_stack built a private stack
    stack = _frame_stack(frames)
    count = formula.count
    _require_count(stack, f"exactly {count}", stack.shape[0] == count)
    sign = 1.0 if direction == "ccw" else -1.0
    steps = sign * np.arange(count) * formula.step + 0.0
    if stack.dtype not in _FAST_DTYPES:
        return _demodulate(stack, formula.weights(sign), steps, formula.name)
    phase, modulation = _fixed_step_maps(stack, formula, sign)
    kept = stack if fresh else stack.copy()  # background and quality are computed from it on demand
    kept.flags.writeable = False
    return PhaseResult(
        phase=phase,
        modulation=modulation,
        steps=_readonly(steps),
        method=formula.name,
        _fringe=_FringeMaps(frames=kept, weights=formula.a_weights, modulation=modulation),
    )


def _combine(rows: NDArray, terms: tuple[tuple[int, int], ...]) -> NDArray:
    """``sum(sign * rows[index])`` over the terms, formed in place in the row of a positive term."""
    ordered = sorted(terms, key=lambda term: -term[1])  # a positive term first
    total = rows[ordered[0][0]]
    for index, term_sign in ordered[1:]:
        (np.add if term_sign > 0 else np.subtract)(total, rows[index], out=total)
    return total


def _fixed_step_maps(
    stack: NDArray, formula: _Formula, sign: float
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Float32 (phase, modulation) of a fixed-step formula, row block by row block.

    Each block of the N frames is widened once (int16 for 8-bit frames, int32 for 16-bit,
    float32 stays float32) and ``C`` and ``S`` are summed in place in it: exactly, for
    integers, and still exact after the conversion to float32 (|sum| < 2**24). The phase needs
    only the ratio ``S / C``, so the sums stay unscaled and the magnitude is scaled once. With
    integers a nonzero ``S`` is at least 1 against ``|C| <= 2**18``, so the phase cannot round
    to ``-float32(pi)`` (it stays more than 3e-6 rad away), and ``S = 0`` is +0 (giving +pi for
    ``C < 0``): no wrap fix is needed. Float32 frames need the fix and a finiteness check.
    """
    count, rows, cols = stack.shape
    s_terms = formula.s_terms if sign > 0 else tuple((index, -s) for index, s in formula.s_terms)
    integer = stack.dtype.kind in "iu"
    wide_dtype = (np.int16 if stack.dtype.itemsize == 1 else np.int32) if integer else np.float32
    maps = np.empty((2, rows, cols), dtype=np.float32)
    block_rows = max(1, min(rows, _FAST_BLOCK_PIXELS // cols))
    wide = np.empty((count, block_rows, cols), dtype=wide_dtype)
    converted = np.empty((2, block_rows, cols), dtype=np.float32) if integer else None
    scale = np.float32(formula.scale)
    for start in range(0, rows, block_rows):
        stop = min(start + block_rows, rows)
        used = stop - start
        block = wide[:, :used]
        np.copyto(block, stack[:, start:stop])
        c = _combine(block, formula.c_terms)
        s = _combine(block, s_terms)
        if formula.s_factor != 1:
            s *= formula.s_factor
        if converted is not None:
            c_float, s_float = converted[:, :used]
            np.copyto(c_float, c)
            np.copyto(s_float, s)
        else:
            c_float, s_float = c, s
            if not (np.isfinite(c).all() and np.isfinite(s).all()):
                raise ValueError("frames: expected finite values, found NaN or infinity")
        phase, modulation = maps[0, start:stop], maps[1, start:stop]
        np.arctan2(s_float, c_float, out=phase)
        if converted is None:  # -0.0 or a tiny negative S with C < 0 gives -pi: send it to +pi
            np.copyto(phase, _FLOAT32_PI, where=phase == -_FLOAT32_PI)
        cv2.magnitude(c_float, s_float, magnitude=modulation)
        modulation *= scale
    maps.flags.writeable = False
    return maps[0], maps[1]
