"""The last step shared by every PSI method: (3, N) weights applied to the frames, and its result.

Every algorithm of :mod:`wavestack.pipeline.phase.psi` ends by applying a (3, N) matrix of
weights to the N frames, giving (A, C, S) per pixel, then ``phi = atan2(S, C)`` and ``B =
hypot(C, S)`` (:func:`_demodulate`, one pass over the frames in blocks that stay in cache). The
result is a :class:`PhaseResult`. "The module docstring" in the docstrings below is that of
:mod:`wavestack.pipeline.phase.psi`: the sign convention, the quality map and the fast path of
the fixed-step formulas.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["PhaseResult"]

_BLOCK_PIXELS = 1 << 16  # pixels per block of the final demodulation: N frames + outputs stay in cache
_RANK_TOLERANCE = 1e-4  # smallest accepted singular-value ratio of a design matrix


class _FringeMaps:
    """Background ``A`` and visibility ``B / A`` of a :class:`PhaseResult`, given or computed on first use.

    Holds either both finished maps, or a private (N, rows, cols) copy of the frames with the
    (N,) weights giving ``A``; the first request computes both maps in float32 from the
    frames and ``modulation``, then drops the frames. Thread-safe.
    """

    __slots__ = ("_frames", "_weights", "_modulation", "_background", "_quality", "_lock")

    def __init__(
        self,
        *,
        background: NDArray[np.floating] | None = None,
        quality: NDArray[np.floating] | None = None,
        frames: NDArray | None = None,
        weights: tuple[float, ...] = (),
        modulation: NDArray[np.float32] | None = None,
    ) -> None:
        self._background = background
        self._quality = quality
        self._frames = frames
        self._weights = weights
        self._modulation = modulation
        self._lock = threading.Lock()

    def maps(self) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
        """(background, quality), read-only, computing them if not done yet."""
        with self._lock:
            if self._background is None or self._quality is None:
                self._compute()
            return self._background, self._quality  # type: ignore[return-value]

    def __getstate__(self) -> dict[str, NDArray[np.floating]]:
        background, quality = self.maps()  # pickle the finished maps, not the frames and the lock
        return {"background": background, "quality": quality}

    def __setstate__(self, state: dict[str, NDArray[np.floating]]) -> None:
        self.__init__(background=state["background"], quality=state["quality"])  # type: ignore[misc]

    def _compute(self) -> None:
        frames, modulation = self._frames, self._modulation
        assert frames is not None and modulation is not None
        background = np.zeros(modulation.shape, dtype=np.float32)
        for frame, weight in zip(frames, self._weights):
            if weight:
                background += frame * np.float32(weight)  # float32 (the weights are k / 8)
        quality = np.zeros(modulation.shape, dtype=np.float32)
        np.divide(modulation, background, out=quality, where=background > 0)
        np.clip(quality, 0.0, 1.0, out=quality)
        self._background, self._quality = _readonly(background), _readonly(quality)
        self._frames = self._modulation = None


@dataclass(frozen=True, eq=False)
class PhaseResult:
    """Wrapped phase and the fringe parameters recovered from a set of phase-shifted frames.

    All maps are read-only arrays of shape (rows, cols): float32 from the fast path of
    :func:`four_step` and :func:`hariharan_five_step` (frames of integers of up to 16 bits, or
    float32; see the module docstring), float64 otherwise.

    Attributes
    ----------
    phase : ndarray of float64 or float32, shape (rows, cols)
        Wrapped phase ``phi`` of the first frame, radians in (-pi, pi]; sign convention in the
        module docstring. Float32 maps hold (-float32(pi), float32(pi)], float32(pi) being
        8.7e-8 above pi: compare in float32 (``phase <= np.pi`` does, NumPy >= 2).
    modulation : ndarray of float64 or float32, shape (rows, cols)
        Fringe amplitude ``B``, in the intensity units of the frames.
    background : ndarray of float64 or float32, shape (rows, cols)
        Background ``A``, in the intensity units of the frames (a property: on the fast path it
        is computed on first access).
    quality : ndarray of float64 or float32, shape (rows, cols)
        Fringe visibility ``B / A`` clipped to [0, 1]; 0 where ``A <= 0`` (a property, like
        ``background``).
    steps : ndarray of float64, shape (N,)
        Phase steps ``delta_k`` used for the demodulation (estimated by ``aia`` and ``pca``),
        radians, ``delta_0 = 0``, unwrapped so consecutive steps differ by less than pi.
    method : str
        "four", "hariharan", "lsq", "aia" or "pca".
    iterations : int or None
        Iterations the AIA took; None for the direct methods.
    """

    phase: NDArray[np.floating]
    modulation: NDArray[np.floating]
    steps: NDArray[np.float64]
    method: str
    iterations: int | None = None
    _fringe: _FringeMaps = field(kw_only=True, repr=False)

    @property
    def background(self) -> NDArray[np.floating]:
        """Background ``A`` (see the class docstring)."""
        return self._fringe.maps()[0]

    @property
    def quality(self) -> NDArray[np.floating]:
        """Fringe visibility ``B / A`` clipped to [0, 1] (see the class docstring)."""
        return self._fringe.maps()[1]


def _work_dtype(dtype: np.dtype) -> type[np.floating]:
    """float32 where it holds the data exactly enough (<= 16-bit integers, float16/32), else float64."""
    if (dtype.kind in "iu" and dtype.itemsize <= 2) or (dtype.kind == "f" and dtype.itemsize <= 4):
        return np.float32
    return np.float64


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
        steps=_readonly(np.asarray(steps, dtype=np.float64).copy()),
        method=method,
        iterations=iterations,
        _fringe=_FringeMaps(background=maps[2], quality=maps[3]),
    )
