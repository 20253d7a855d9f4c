"""What one simulated PI GCS controller is: its axes, travel limits, velocity, pivot and identity.

The same settings describe the C-887 hexapod (six axes X Y Z U V W, a pivot point R S T) and the
bench's two-axis field stage (axes X Y, no pivot): nothing in the simulator assumes six axes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

__all__ = ["HEXAPOD_AXES", "HexapodSimSettings"]

#: The hexapod's axes: translations X Y Z (mm), rotations U V W (deg) about X, Y, Z.
HEXAPOD_AXES = ("X", "Y", "Z", "U", "V", "W")
_AXIS_NAME = re.compile(r"^[A-Za-z0-9_]{1,8}$")
_DEFAULT_IDN = "Physik Instrumente (PI) GmbH & Co. KG, C-887.52, SIM0000001, wavestack simulator 1.0"


@dataclass(frozen=True)
class HexapodSimSettings:
    """Settings of one simulated GCS 2.0 controller (frozen; checked on construction).

    Parameters
    ----------
    axes
        Axis identifiers in controller order (``SAI?`` lists them in this order; bit ``i`` of the
        ``#5`` answer is axis ``i``).
    low_limits, high_limits
        Travel range per axis (what ``TMN?``/``TMX?`` answer), mm or deg; a ``MOV`` outside is
        refused with error 7. The defaults are of the order of PI's mid-size hexapods (H-820 class:
        tens of mm, tens of degrees); the real workspace is coupled (a large X limits the
        reachable U), which this box model does not know.
    velocity
        Power-on system velocity (``VLS``), units per second, used by every axis.
    max_velocity
        Largest velocity ``VLS`` accepts (above it: error 8).
    pivot
        Pivot point (R, S, T), mm, or None for a stage without rotations (``SPI`` is then an
        unknown command).
    pivot_limit_mm
        Largest |R|, |S|, |T| the controller takes, mm (``SPI`` beyond it: error 17).
    initial_position
        Power-on positions, one per axis (None: all zero); must lie within the limits.
    idn
        The ``*IDN?`` answer.
    referenced, servo
        Power-on reference state and servo state of every axis.
    reference_time_s
        Shortest duration of a reference move (``FRF``), simulated seconds.

    Raises
    ------
    ValueError
        Repeated or malformed axis names, tuples of the wrong length, empty ranges, a start
        position outside the limits, or a velocity outside (0, max_velocity].

    Examples
    --------
    >>> stage = HexapodSimSettings(axes=("X", "Y"), low_limits=(-50.0, -50.0), high_limits=(50.0, 50.0),
    ...                            pivot=None)
    >>> stage.axes, stage.initial_position
    (('X', 'Y'), (0.0, 0.0))
    """

    axes: tuple[str, ...] = HEXAPOD_AXES
    low_limits: tuple[float, ...] = (-17.0, -16.0, -6.5, -14.5, -14.5, -20.0)
    high_limits: tuple[float, ...] = (17.0, 16.0, 6.5, 14.5, 14.5, 20.0)
    velocity: float = 2.0
    max_velocity: float = 20.0
    pivot: tuple[float, float, float] | None = (0.0, 0.0, 0.0)
    pivot_limit_mm: float = 1000.0
    initial_position: tuple[float, ...] | None = None
    idn: str = _DEFAULT_IDN
    referenced: bool = True
    servo: bool = True
    reference_time_s: float = 0.2

    def __post_init__(self) -> None:
        axes = tuple(self.axes)
        if not axes or len(set(axes)) != len(axes) or not all(_AXIS_NAME.match(a) for a in axes):
            raise ValueError(f"axes: expected distinct identifiers of 1-8 letters or digits, got {list(axes)}")
        n = len(axes)
        for name in ("low_limits", "high_limits"):
            values = getattr(self, name)
            if len(values) != n or not all(math.isfinite(v) for v in values):
                raise ValueError(f"{name}: expected {n} finite values (one per axis {list(axes)}), got {list(values)}")
        for axis, lo, hi in zip(axes, self.low_limits, self.high_limits):
            if not lo < hi:
                raise ValueError(f"limits of axis {axis}: expected low < high, got [{lo}, {hi}]")
        start = self.initial_position if self.initial_position is not None else tuple(
            min(max(0.0, lo), hi) for lo, hi in zip(self.low_limits, self.high_limits))
        if len(start) != n or not all(lo <= p <= hi for p, lo, hi in zip(start, self.low_limits, self.high_limits)):
            raise ValueError(f"initial_position: expected {n} values within the limits, got {list(start)}")
        if not 0.0 < self.max_velocity < math.inf or not 0.0 < self.velocity <= self.max_velocity:
            raise ValueError(f"velocity: expected 0 < velocity <= max_velocity ({self.max_velocity}), "
                             f"got {self.velocity}")
        if not 0.0 < self.pivot_limit_mm < math.inf:
            raise ValueError(f"pivot_limit_mm: expected a finite value > 0, got {self.pivot_limit_mm}")
        if self.pivot is not None and (len(self.pivot) != 3
                                       or not all(abs(p) <= self.pivot_limit_mm for p in self.pivot)):
            raise ValueError(f"pivot: expected 3 coordinates (R, S, T) within +-{self.pivot_limit_mm:g} mm, or None, "
                             f"got {self.pivot}")
        if not 0.0 <= self.reference_time_s < math.inf:
            raise ValueError(f"reference_time_s: expected >= 0, got {self.reference_time_s}")
        if any(ch in self.idn for ch in "\r\n"):
            raise ValueError("idn: expected one line (no CR or LF)")
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "low_limits", tuple(float(v) for v in self.low_limits))
        object.__setattr__(self, "high_limits", tuple(float(v) for v in self.high_limits))
        object.__setattr__(self, "initial_position", tuple(float(v) for v in start))
        if self.pivot is not None:
            object.__setattr__(self, "pivot", tuple(float(v) for v in self.pivot))
