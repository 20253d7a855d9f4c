"""Voltage limits of the MDT693B / MDT694B: an axis's effective range and the setpoint on the wire.

The range :meth:`~wavestack.drivers.mdt693b.driver.MDT693B.set_voltage` accepts is the tightest of
three: the driver's software limits, the controller's per-axis ``<axis>min?``/``<axis>max?`` and its
front-panel limit switch (``vlimit?``). Pure functions and values, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wavestack.drivers.errors import LimitError


@dataclass(frozen=True)
class AxisLimits:
    """The voltage range :meth:`MDT693B.set_voltage` accepts on one axis.

    Attributes
    ----------
    min_v, max_v
        Effective range, V: the higher of the software minimum and ``<axis>min?``; the lowest of
        the software maximum, ``<axis>max?`` and the front-panel limit switch (``vlimit?``).
    device_min_v, device_max_v
        ``<axis>min?`` and ``<axis>max?`` as read at open, V.
    vlimit_v
        The limit switch setting, V (75, 100 or 150).
    """

    min_v: float
    max_v: float
    device_min_v: float
    device_max_v: float
    vlimit_v: float

    def contains(self, volts: float) -> bool:
        """True when ``min_v <= volts <= max_v``."""
        return self.min_v <= volts <= self.max_v

    def clamp(self, volts: float) -> float:
        """``volts`` moved into ``[min_v, max_v]``."""
        return min(max(volts, self.min_v), self.max_v)


def _effective_limits(device: str, axis: str, *, software_min_v: float, software_max_v: float,
                      device_min_v: float, device_max_v: float, vlimit_v: float) -> AxisLimits:
    """The :class:`AxisLimits` of ``axis``: software limits narrowed by the device's and the limit switch.

    Parameters
    ----------
    device
        Who raises, in messages (the driver's name).
    axis
        ``"x"``, ``"y"`` or ``"z"``.
    software_min_v, software_max_v
        The driver's software limits, V.
    device_min_v, device_max_v
        ``<axis>min?`` and ``<axis>max?``, V.
    vlimit_v
        The front-panel limit switch (``vlimit?``), V.

    Raises
    ------
    LimitError
        The three ranges leave no usable voltage, or none that two decimals (the resolution of a
        setpoint on the wire) can spell.
    """
    low = max(software_min_v, device_min_v)
    high = min(software_max_v, device_max_v, vlimit_v)
    if low > high or _wire_at_or_above(low) > high:
        narrow = "" if low > high else f" with a two-decimal voltage (the wire's resolution) in [{low}, {high}]"
        raise LimitError(device, f"axis {axis} has no usable range{narrow}: software "
                         f"[{software_min_v:g}, {software_max_v:g}] V, device "
                         f"[{device_min_v:g}, {device_max_v:g}] V, limit switch {vlimit_v:g} V")
    return AxisLimits(low, high, device_min_v, device_max_v, vlimit_v)


def _wire_at_or_above(volts: float) -> float:
    """The smallest voltage with two decimals that is >= ``volts`` (exact despite ``volts * 100`` rounding)."""
    cents = math.ceil(volts * 100)
    return (cents - 1) / 100 if (cents - 1) / 100 >= volts else cents / 100


def _wire_at_or_below(volts: float) -> float:
    """The largest voltage with two decimals that is <= ``volts``."""
    cents = math.floor(volts * 100)
    return (cents + 1) / 100 if (cents + 1) / 100 <= volts else cents / 100


def _on_wire(volts: float, limits: AxisLimits) -> float:
    """The voltage as sent (two decimals), kept inside ``limits`` when rounding would leave them."""
    wire = round(volts, 2)
    if wire > limits.max_v:
        wire = _wire_at_or_below(limits.max_v)
    if wire < limits.min_v:
        wire = _wire_at_or_above(limits.min_v)
    return wire
