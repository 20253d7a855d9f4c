"""The last check before a machine program leaves the host: every point against the machine's limits."""

from __future__ import annotations

import math
import numpy as np
from numpy.typing import NDArray

from .feed import segment_lengths_mm
from .limits import MachineLimits
from .machine_program import PATHS, MachineProgram

FEED_DWELL_RTOL = 1e-6
"""How far ``feed_mm_s[k] * dwell_s[k]`` may differ from the move's length (relative)."""

_ROUNDING_ULPS = 8.0  # slack on squared speeds in the acceleration check: rounding, not physics


class ProgramRejected(ValueError):
    """A machine program that breaks one of the machine's limits, or cannot be made to fit them.

    Attributes
    ----------
    point_index : int or None
        Index of the offending point (None for a rule on the whole program).
    quantity : str
        What broke the rule (``"dwell_s"``, ``"feed_mm_s"``, ``"acceleration_mm_s2"``, ...).
    value : object
        Its value.
    limit : object
        The limit it broke (a number, or a short description such as ``"> 0"``).
    """

    def __init__(self, quantity: str, value: object, limit: object, point_index: int | None = None) -> None:
        self.point_index = point_index
        self.quantity = quantity
        self.value = value
        self.limit = limit
        where = "program" if point_index is None else f"point {point_index}"
        super().__init__(f"machine program rejected at {where}: {quantity} is {value!r}, limit {limit}")


def check_program(program: MachineProgram, limits: MachineLimits) -> None:
    """Refuse a program the machine must not run; return None when it passes.

    The rules, checked in this order (the first broken one is raised, at its first point):
    a known path kind and finite step_mm, pixel_mm > 0; four 1-D arrays of one length, not
    empty; every value finite; every point inside the travel; ``0 < dwell_s <=
    max_dwell_per_point_s``; ``0 < feed_mm_s <= max_feed_mm_s``; ``feed_mm_s * dwell_s`` equal
    to the length of the move into the point (``step_mm`` for the first), within
    :data:`FEED_DWELL_RTOL`, so the dwell implies the same feed; the path acceleration
    ``|v_k^2 - v_{k-1}^2| / (2 s_k)`` at most ``max_accel_mm_s2``, starting from and ending at
    rest (within one step); the total dwell at most ``max_total_dwell_s``.

    Parameters
    ----------
    program : MachineProgram
    limits : MachineLimits

    Raises
    ------
    ProgramRejected
        Naming the point index, the quantity, its value and the limit.

    Examples
    --------
    >>> from wavestack.pipeline.polishing.machine_program import MachineProgram
    >>> limits = MachineLimits(10.0, 1e4, (-5.0, 5.0), (-5.0, 5.0), 2.0, 100.0)
    >>> ok = MachineProgram([0.0, 1.0], [0.0, 0.0], [0.5, 0.5], [2.0, 2.0], "raster", 1.0, 1.0)
    >>> check_program(ok, limits)
    >>> bad = MachineProgram([0.0, 9.0], [0.0, 0.0], [0.5, 4.5], [2.0, 2.0], "raster", 1.0, 1.0)
    >>> check_program(bad, limits)
    Traceback (most recent call last):
    ...
    wavestack.pipeline.polishing.program_checks.ProgramRejected: machine program rejected at point 1: x_mm is 9.0, limit (-5.0, 5.0)
    """
    arrays = _structure(program)
    x, y, dwell, feed = arrays
    for name, values in zip(("x_mm", "y_mm", "dwell_s", "feed_mm_s"), arrays):
        _first(name, values, ~np.isfinite(values), "finite")
    _first("x_mm", x, (x < limits.travel_x_mm[0]) | (x > limits.travel_x_mm[1]), limits.travel_x_mm)
    _first("y_mm", y, (y < limits.travel_y_mm[0]) | (y > limits.travel_y_mm[1]), limits.travel_y_mm)
    _first("dwell_s", dwell, dwell <= 0, "> 0")
    _first("dwell_s", dwell, dwell > limits.max_dwell_per_point_s, limits.max_dwell_per_point_s)
    _first("feed_mm_s", feed, feed <= 0, "> 0")
    _first("feed_mm_s", feed, feed > limits.max_feed_mm_s, limits.max_feed_mm_s)
    segment = segment_lengths_mm(x, y, program.step_mm)
    travelled = feed * dwell
    _first("feed_mm_s * dwell_s (mm)", travelled, np.abs(travelled - segment) > FEED_DWELL_RTOL * segment,
           "the length of the move into the point")
    _check_acceleration(feed, segment, program.step_mm, limits.max_accel_mm_s2)
    total = float(np.sum(dwell))
    if total > limits.max_total_dwell_s:
        raise ProgramRejected("total dwell_s", total, limits.max_total_dwell_s)


def _structure(program: MachineProgram) -> tuple[NDArray[np.float64], ...]:
    if program.path not in PATHS:
        raise ProgramRejected("path", program.path, f"one of {PATHS}")
    for name in ("step_mm", "pixel_mm"):
        value = getattr(program, name)
        if not (isinstance(value, float) and math.isfinite(value) and value > 0):
            raise ProgramRejected(name, value, "finite and > 0")
    arrays = (program.x_mm, program.y_mm, program.dwell_s, program.feed_mm_s)
    for name, values in zip(("x_mm", "y_mm", "dwell_s", "feed_mm_s"), arrays):
        if values.ndim != 1:
            raise ProgramRejected(f"shape of {name}", values.shape, "(K,)")
        if values.size != arrays[0].size:
            raise ProgramRejected(f"length of {name}", values.size, f"{arrays[0].size} (the length of x_mm)")
    if arrays[0].size == 0:
        raise ProgramRejected("point count", 0, ">= 1")
    return arrays


def _first(quantity: str, values: NDArray[np.float64], bad: NDArray[np.bool_], limit: object) -> None:
    hits = np.flatnonzero(bad)
    if hits.size:
        k = int(hits[0])
        raise ProgramRejected(quantity, float(values[k]), limit, k)


def _check_acceleration(
    feed: NDArray[np.float64], segment: NDArray[np.float64], step_mm: float, max_accel: float
) -> None:
    """Path acceleration between neighbours, from rest before the first point and to rest after the last."""
    squared = feed * feed
    before = np.concatenate(([0.0], squared[:-1]))
    change = np.abs(squared - before)
    slack = _ROUNDING_ULPS * np.finfo(np.float64).eps * np.maximum(squared, before)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero-length move is refused earlier
        accel = change / (2.0 * segment)
    _first("acceleration_mm_s2", accel, change - slack > 2.0 * max_accel * segment, max_accel)
    stop = squared[-1] / (2.0 * step_mm)
    if squared[-1] - slack[-1] > 2.0 * max_accel * step_mm:
        raise ProgramRejected(
            "acceleration_mm_s2 (stopping after the last point)", float(stop), max_accel, feed.size - 1
        )
