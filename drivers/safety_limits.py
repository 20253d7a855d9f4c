"""The limits the safety stage enforces on one actuator output: a validated, immutable value.

:class:`SafetyLimits` holds, per channel, the drive limits (EPICS ao ``DRVL``/``DRVH``), the rate
limit (``OROC``), the staleness bounds and the invalid-output action (``IVOA``/``IVOV``) that
:class:`~wavestack.drivers.safety.SafetyStage` applies; see :mod:`wavestack.drivers.safety` for the
processing and the EPICS references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.drivers._checks import is_number

__all__ = ["InvalidAction", "SafetyLimits"]

InvalidAction = Literal["hold", "safe_value"]
_INVALID_ACTIONS: tuple[str, ...] = ("hold", "safe_value")


def _frozen_vector(value: ArrayLike, n: int, name: str) -> NDArray[np.float64]:
    """``value`` as a read-only float64 (n,) copy (a scalar is broadcast); ValueError naming ``name``."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"SafetyLimits.{name}: expected numbers, got {value!r}") from exc
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"SafetyLimits.{name}: expected shape ({n},) like the other limits, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"SafetyLimits.{name}: every value must be finite, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class SafetyLimits:
    """Per-channel limits of one actuator output (immutable; arrays are read-only copies).

    Parameters
    ----------
    lower, upper
        Drive limits (EPICS ``DRVL``/``DRVH``), shape (n,) or scalars broadcast to n, in the
        actuator's units (V, nm, ...). ``lower < upper`` on every channel.
    max_step
        Largest change of the output per update (EPICS ``OROC``), shape (n,) or scalar, ``> 0``,
        same units. It must exceed the float64 resolution of the limits (else the output could
        never move).
    max_age_s
        A request whose measurement is older than this (``now_s - measured_at_s``) is stale, s.
    invalid_action
        ``"hold"`` keeps the last output on invalid input; ``"safe_value"`` moves it toward
        ``safe_value`` by at most ``max_step`` per update.
    safe_value
        Shape (n,) or scalar, within ``[lower, upper]``: the target of ``"safe_value"`` and the
        stage's initial output.
    max_future_s
        Clock-skew tolerance: a measurement time-stamped more than this after ``now_s`` is treated
        as stale (s, ``>= 0``).

    Raises
    ------
    ValueError
        Naming the field: shapes disagree, a value is not finite, ``lower >= upper``,
        ``max_step <= 0`` or below resolution, ``max_age_s <= 0``, unknown ``invalid_action``,
        ``safe_value`` outside the limits.
    """

    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    max_step: NDArray[np.float64]
    max_age_s: float
    invalid_action: InvalidAction = "hold"
    safe_value: NDArray[np.float64] | float = 0.0
    max_future_s: float = 0.01

    def __post_init__(self) -> None:
        shapes = {
            name: np.shape(getattr(self, name)) for name in ("lower", "upper", "max_step", "safe_value")
        }
        vector_lengths = [shape[0] for shape in shapes.values() if len(shape) == 1]
        n = vector_lengths[0] if vector_lengths else 1
        if n < 1:
            raise ValueError("SafetyLimits.lower: at least one channel is required, got shape (0,)")
        for name in ("lower", "upper", "max_step", "safe_value"):
            object.__setattr__(self, name, _frozen_vector(getattr(self, name), n, name))
        bad = np.flatnonzero(~(self.lower < self.upper))
        if bad.size:
            raise ValueError(
                f"SafetyLimits.upper: must exceed lower on every channel; channels {bad.tolist()} "
                f"have lower={self.lower[bad].tolist()}, upper={self.upper[bad].tolist()}"
            )
        resolution = 1024.0 * np.spacing(np.maximum(np.abs(self.lower), np.abs(self.upper)))
        bad = np.flatnonzero(~(self.max_step > resolution))
        if bad.size:
            raise ValueError(
                f"SafetyLimits.max_step: must be > 0 and above the float64 resolution of the limits "
                f"(> {resolution[bad].tolist()}) on channels {bad.tolist()}, "
                f"got {self.max_step[bad].tolist()}"
            )
        bad = np.flatnonzero((self.safe_value < self.lower) | (self.safe_value > self.upper))
        if bad.size:
            raise ValueError(
                f"SafetyLimits.safe_value: must lie within [lower, upper]; channels {bad.tolist()} have "
                f"{self.safe_value[bad].tolist()} outside lower={self.lower[bad].tolist()}, "
                f"upper={self.upper[bad].tolist()}"
            )
        for name in ("max_age_s", "max_future_s"):
            value = getattr(self, name)
            if not (is_number(value) and math.isfinite(value)):
                raise ValueError(f"SafetyLimits.{name}: expected a finite number of seconds, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.max_age_s <= 0.0:
            raise ValueError(f"SafetyLimits.max_age_s: must be > 0 s, got {self.max_age_s}")
        if self.max_future_s < 0.0:
            raise ValueError(f"SafetyLimits.max_future_s: must be >= 0 s, got {self.max_future_s}")
        if self.invalid_action not in _INVALID_ACTIONS:
            raise ValueError(
                f"SafetyLimits.invalid_action: expected one of {_INVALID_ACTIONS}, "
                f"got {self.invalid_action!r}"
            )

    @property
    def n_channels(self) -> int:
        """Number of channels n."""
        return int(self.lower.shape[0])
