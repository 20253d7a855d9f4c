"""Move limits of a PI GCS platform, and the pure check every move passes before anything is sent.

Three limits apply to each axis of a move, all read or configured before it:

1. the controller's travel range, ``TMN?`` / ``TMX?`` (read once when the driver connects);
2. the configured soft limits, :attr:`HexapodLimits.soft` (inclusive);
3. the configured largest step per move, :attr:`HexapodLimits.max_step`, counted from the
   position *read back* (``POS?``) just before the move.

A move that breaks any of them is refused whole: nothing is sent and the error names every axis
at fault. A pose is never clipped or cut to a smaller step: a hexapod's six coordinates only mean
something together (a clipped rotation about the pivot moves every strut differently from what
the caller computed), so a changed pose is a wrong pose. This is the EPICS-ao-style safety stage
of :mod:`wavestack.drivers.safety` with its clipping and rate limiting turned into refusals; the
driver also runs the move through a :class:`~wavestack.drivers.safety.SafetyStage` and refuses
unless the stage forwards it unchanged (:func:`safety_limits`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

from wavestack.drivers._checks import is_number
from wavestack.drivers.pi_gcs.protocol import check_axis_id
from wavestack.drivers.safety import SafetyLimits

__all__ = ["HexapodLimits", "effective_range", "move_refusals", "safety_limits"]


def _finite(value: object, what: str) -> float:
    if not (is_number(value) and math.isfinite(float(value))):  # type: ignore[arg-type]
        raise ValueError(f"HexapodLimits.{what}: expected a finite number, got {value!r}")
    return float(value)  # type: ignore[arg-type]


@dataclass(frozen=True, eq=False)
class HexapodLimits:
    """Configured soft limits and largest step per move, per axis (immutable).

    Parameters
    ----------
    soft
        ``{axis: (lower, upper)}``, inclusive, in the axis's units (mm for X Y Z, deg for U V W).
    max_step
        ``{axis: step}``, > 0, same units: the largest ``|target - position read back|`` one move
        may ask for.

    Raises
    ------
    ValueError
        Naming the field and axis: a bad axis identifier, a non-finite value, ``lower >= upper``,
        ``step <= 0``, or an axis in one mapping but not the other.

    Examples
    --------
    >>> limits = HexapodLimits.uniform(("X", "Y"), lower=-5.0, upper=5.0, max_step=0.5)
    >>> limits.soft["X"], limits.max_step["Y"]
    ((-5.0, 5.0), 0.5)
    """

    soft: Mapping[str, tuple[float, float]]
    max_step: Mapping[str, float]

    def __post_init__(self) -> None:
        soft: dict[str, tuple[float, float]] = {}
        for axis, pair in dict(self.soft).items():
            check_axis_id(axis)
            if not isinstance(pair, Sequence) or len(pair) != 2:
                raise ValueError(f"HexapodLimits.soft[{axis!r}]: expected (lower, upper), got {pair!r}")
            lower, upper = _finite(pair[0], f"soft[{axis!r}]"), _finite(pair[1], f"soft[{axis!r}]")
            if not lower < upper:
                raise ValueError(f"HexapodLimits.soft[{axis!r}]: expected lower < upper, got ({lower}, {upper})")
            soft[axis] = (lower, upper)
        steps: dict[str, float] = {}
        for axis, step in dict(self.max_step).items():
            steps[axis] = _finite(step, f"max_step[{axis!r}]")
            if not steps[axis] > 0.0:
                raise ValueError(f"HexapodLimits.max_step[{axis!r}]: expected > 0, got {steps[axis]}")
        if set(soft) != set(steps):
            raise ValueError(f"HexapodLimits: soft and max_step must name the same axes, got soft "
                             f"{sorted(soft)} and max_step {sorted(steps)}")
        object.__setattr__(self, "soft", MappingProxyType(soft))
        object.__setattr__(self, "max_step", MappingProxyType(steps))

    @classmethod
    def uniform(cls, axes: Sequence[str], *, lower: float, upper: float, max_step: float) -> HexapodLimits:
        """The same soft range and step on every axis of ``axes``."""
        return cls(soft={axis: (lower, upper) for axis in axes}, max_step={axis: max_step for axis in axes})

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes these limits cover."""
        return tuple(self.soft)


def effective_range(limits: HexapodLimits, controller: Mapping[str, tuple[float, float]],
                    axis: str) -> tuple[float, float]:
    """The tighter of the soft limits and the controller's travel range (``TMN?``/``TMX?``) on ``axis``."""
    soft_lo, soft_hi = limits.soft[axis]
    ctrl_lo, ctrl_hi = controller[axis]
    return max(soft_lo, ctrl_lo), min(soft_hi, ctrl_hi)


def move_refusals(target: Mapping[str, float], current: Mapping[str, float], limits: HexapodLimits,
                  controller: Mapping[str, tuple[float, float]]) -> list[str]:
    """Why the move to ``target`` may not be sent, one reason per fault; empty when it may (pure).

    Parameters
    ----------
    target
        ``{axis: value}`` as the controller will receive it (see
        :func:`~wavestack.drivers.pi_gcs.protocol.quantize`); a subset of the limited axes.
    current
        Position read back, ``{axis: value}`` for every axis of ``target``.
    limits
        Soft limits and largest step.
    controller
        The controller's travel range ``{axis: (TMN, TMX)}``.

    Examples
    --------
    >>> limits = HexapodLimits.uniform(("X", "Z"), lower=-5.0, upper=5.0, max_step=0.5)
    >>> travel = {"X": (-10.0, 10.0), "Z": (-3.0, 3.0)}
    >>> move_refusals({"X": 0.4, "Z": 0.0}, {"X": 0.0, "Z": 0.0}, limits, travel)
    []
    >>> move_refusals({"X": 0.6, "Z": 4.0}, {"X": 0.0, "Z": 3.9}, limits, travel)  # doctest: +NORMALIZE_WHITESPACE
    ['X: step 0.6 from the position read back 0 exceeds max_step 0.5',
     'Z: 4 outside the controller travel range [-3, 3] (TMN?/TMX?)']
    """
    reasons: list[str] = []
    for axis, value in target.items():
        if axis not in limits.soft or axis not in controller:
            reasons.append(f"{axis}: no limits known for this axis")
            continue
        if not math.isfinite(value):
            reasons.append(f"{axis}: target {value!r} is not a finite number")
            continue
        ctrl_lo, ctrl_hi = controller[axis]
        soft_lo, soft_hi = limits.soft[axis]
        step = abs(value - current[axis])
        if not ctrl_lo <= value <= ctrl_hi:
            reasons.append(f"{axis}: {value:g} outside the controller travel range [{ctrl_lo:g}, {ctrl_hi:g}] "
                           "(TMN?/TMX?)")
        elif not soft_lo <= value <= soft_hi:
            reasons.append(f"{axis}: {value:g} outside the soft limits [{soft_lo:g}, {soft_hi:g}]")
        elif not step <= limits.max_step[axis]:
            reasons.append(f"{axis}: step {step:g} from the position read back {current[axis]:g} exceeds "
                           f"max_step {limits.max_step[axis]:g}")
    return reasons


def safety_limits(limits: HexapodLimits, controller: Mapping[str, tuple[float, float]],
                  axes: Sequence[str]) -> SafetyLimits:
    """The :class:`SafetyLimits` of the driver's safety stage: effective ranges and steps over ``axes``.

    Raises
    ------
    ValueError
        An axis whose soft limits and controller travel range do not overlap.
    """
    ranges = [effective_range(limits, controller, axis) for axis in axes]
    empty = [axis for axis, (lo, hi) in zip(axes, ranges) if not lo < hi]
    if empty:
        raise ValueError(f"HexapodLimits.soft: no overlap with the controller travel range on axes {empty} "
                         f"(soft {[limits.soft[a] for a in empty]}, controller {[controller[a] for a in empty]})")
    lower = [lo for lo, _ in ranges]
    upper = [hi for _, hi in ranges]
    safe = [min(max(0.0, lo), hi) for lo, hi in ranges]
    return SafetyLimits(lower=lower, upper=upper, max_step=[limits.max_step[a] for a in axes], max_age_s=1.0,
                        invalid_action="hold", safe_value=safe)
