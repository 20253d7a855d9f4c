"""Phase-shifting interferometry (PSI): the wrapped phase from N frames taken at N phase steps.

Sign convention (project-wide)
------------------------------
Frame ``k`` is modelled as

    I_k(x, y) = A(x, y) + B(x, y) cos(phi(x, y) + delta_k),

where ``delta_k`` are the reference phase steps. *Counter-clockwise* (``direction="ccw"``,
the default, and what the real data in the shared ``psi-mirror-654nm`` data use) means
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

Fast path of the fixed-step formulas
------------------------------------
:func:`four_step` and :func:`hariharan_five_step` given frames of integers of up to 16 bits
(a camera's uint8 / uint16) or float32 do not go through the weights: they form the two
differences ``C`` and ``S`` in integers (exact), convert them once to float32 and take
``atan2`` (numpy, float32) and the magnitude (OpenCV) in row blocks that stay in cache, writing
float32 ``phase`` and ``modulation`` maps. Against the float64 formula the phase differs by at
most a few float32 ulps of pi (measured: 2.8e-7 rad on 1024 x 1024 uint8 frames, 3.3e-7 for
uint16, 3.5e-7 for float32 frames) and the modulation by a relative 4e-7. ``background`` and
``quality`` are computed on first access only, from a private copy of the frames (no copy when
the frames were given as a sequence: the stack built from it is already private). At
1024 x 1024 uint8 this takes about 2.5 ms instead of 17 ms (``benchmarks/bench_psi.py``). Other
dtypes take the float64 path above.

The modules: :mod:`.algorithms` (:func:`phase_from_frames` and the fixed-step formulas),
:mod:`.estimated_steps` (unknown steps), :mod:`.demodulation` (the shared last step),
:mod:`.fast` (integer fast path), :mod:`.inputs` (argument checks).
"""

from __future__ import annotations

from .algorithms import four_step, hariharan_five_step, least_squares_psi, phase_from_frames
from .demodulation import PhaseResult
from .estimated_steps import advanced_iterative_psi, pca_psi

__all__ = [
    "PhaseResult",
    "advanced_iterative_psi",
    "four_step",
    "hariharan_five_step",
    "least_squares_psi",
    "pca_psi",
    "phase_from_frames",
]
