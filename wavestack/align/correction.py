"""The correction sent to the hexapod: a fraction of the estimate, within the step and the limits.

The move is ``target = current - gain * estimated_state`` on X Y Z U V (W keeps its position).
Then, in this order:

1. *max step*: when any axis's step exceeds its ``max_step``, the whole step vector is scaled by
   one factor so that the largest ratio is 1. Scaling (not per-axis clipping) keeps the correction's
   direction: decentre and tilt of a secondary compensate each other (coma-free pivot), and
   clipping one of them alone would send a move the estimate never asked for. It is not split
   into several moves either: the next iteration re-measures and re-linearises, which a blind
   second half-move would skip.
2. *soft limits*: the target is clipped into ``[lower, upper]`` per axis (the current position
   lies inside, so this only shortens steps); the move says so.

The driver checks both again before the wire (``PIHexapod.move_absolute``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline.telescope import DOFS

__all__ = ["PlannedMove", "plan_move"]


@dataclass(frozen=True)
class PlannedMove:
    """A correction ready for ``move_absolute``.

    Attributes
    ----------
    target : dict of str to float
        ``{axis: value}`` for X Y Z U V, mm and deg.
    step : dict of str to float
        ``target - current`` per axis.
    scale : float
        The factor the max step imposed (1: none).
    clipped : tuple of str
        Axes clipped to a soft limit.
    """

    target: dict[str, float]
    step: dict[str, float]
    scale: float
    clipped: tuple[str, ...]


def plan_move(current: Mapping[str, float], state: NDArray[np.floating], *, gain: float,
              max_step: Mapping[str, float], soft: Mapping[str, tuple[float, float]]) -> PlannedMove:
    """The move that removes ``gain`` of the estimated ``state`` (module notes).

    Parameters
    ----------
    current : mapping
        Position read back, at least X Y Z U V.
    state : array (5,)
        Estimated misalignment (X Y Z mm, U V deg).
    gain : float
        0 < gain <= 1.
    max_step, soft : mapping
        Per axis, as in :class:`~wavestack.drivers.pi_gcs.HexapodLimits`.

    Examples
    --------
    >>> soft = {a: (-1.0, 1.0) for a in DOFS}
    >>> m = plan_move({a: 0.0 for a in DOFS}, [0.4, 0, 0, 0.02, 0], gain=1.0,
    ...               max_step={a: 0.2 for a in DOFS}, soft=soft)
    >>> m.scale, m.target["X"], m.target["U"]
    (0.5, -0.2, -0.01)
    """
    state = np.asarray(state, dtype=np.float64)
    if state.shape != (len(DOFS),) or not np.all(np.isfinite(state)):
        raise ValueError(f"state: expected {len(DOFS)} finite values, got {state}")
    if not 0.0 < gain <= 1.0:
        raise ValueError(f"gain: expected 0 < gain <= 1, got {gain}")
    now = np.array([float(current[a]) for a in DOFS])
    limit = np.array([float(max_step[a]) for a in DOFS])
    step = -gain * state
    ratio = float(np.max(np.abs(step) / limit))
    scale = 1.0 if ratio <= 1.0 else 1.0 / ratio
    target = now + step * scale
    lower = np.array([soft[a][0] for a in DOFS])
    upper = np.array([soft[a][1] for a in DOFS])
    clipped = tuple(a for a, t, lo, hi in zip(DOFS, target, lower, upper) if not lo <= t <= hi)
    target = np.clip(target, lower, upper)
    # a step of exactly max_step may round past it on the wire (9 decimals): keep a hair inside
    target = np.where(np.abs(target - now) > limit, now + np.sign(target - now) * limit * (1 - 1e-9), target)
    return PlannedMove({a: float(t) for a, t in zip(DOFS, target)},
                       {a: float(t - n) for a, t, n in zip(DOFS, target, now)}, scale, clipped)
