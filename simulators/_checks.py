"""Argument checks shared by the simulators: numbers, integers, camera sizes and read-only arrays.

Each check raises ``ValueError`` naming the argument, in the wording the simulators' settings have
always used (tests match on it). The driver side keeps its own checks
(:mod:`wavestack.drivers._checks`): a simulator never imports the driver.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "check_bit_depth",
    "check_image_size",
    "check_seed",
    "finite_number",
    "is_integer",
    "is_number",
    "nonnegative_number",
    "number_pair",
    "read_only",
    "read_only_copy",
]


def is_number(value: object) -> bool:
    """True for a Python or numpy int or float, False for a bool or anything else."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def is_integer(value: object) -> bool:
    """True for a Python or numpy integer, False for a bool or anything else."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def finite_number(value: object, name: str, *, minimum: float | None = None, above: float | None = None) -> float:
    """``value`` as a float if it is a finite number (``>= minimum``, ``> above`` when given).

    Raises
    ------
    ValueError
        ``"{name}: expected a number, ..."``, ``"... a finite number, ..."``, ``"... >= minimum, ..."``
        or ``"... > above, ..."``.
    """
    if not is_number(value):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    number = float(value)  # type: ignore[arg-type]
    if not math.isfinite(number):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if minimum is not None and number < minimum:
        raise ValueError(f"{name}: expected >= {minimum}, got {value!r}")
    if above is not None and number <= above:
        raise ValueError(f"{name}: expected > {above}, got {value!r}")
    return number


def nonnegative_number(value: object, name: str) -> float:
    """``value`` as a float if it is a finite number ``>= 0``; ValueError naming ``name`` otherwise."""
    number = finite_number(value, name)
    if number < 0:
        raise ValueError(f"{name}: expected a number >= 0, got {value!r}")
    return number


def number_pair(value: object, name: str) -> tuple[float, float]:
    """``value`` as two finite floats (a ``(col, row)`` pair); ValueError naming ``name`` otherwise."""
    try:
        first, second = value  # type: ignore[misc]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a pair of numbers, got {value!r}") from None
    return finite_number(first, f"{name}[0]"), finite_number(second, f"{name}[1]")


def check_bit_depth(bit_depth: object) -> None:
    """ValueError unless ``bit_depth`` is 8, 12 or 16 (a camera's ADC depth, bits)."""
    if bit_depth not in (8, 12, 16) or isinstance(bit_depth, bool):
        raise ValueError(f"bit_depth: expected 8, 12 or 16, got {bit_depth!r}")


def check_seed(seed: object) -> None:
    """ValueError unless ``seed`` is an integer ``>= 0`` (a random generator's seed)."""
    if not is_integer(seed) or seed < 0:  # type: ignore[operator]
        raise ValueError(f"seed: expected an integer >= 0, got {seed!r}")


def check_image_size(height: object, width: object, minimum: int) -> None:
    """ValueError unless ``height`` and ``width`` are integers ``>= minimum`` pixels."""
    for name, value in (("height", height), ("width", width)):
        if not is_integer(value) or value < minimum:  # type: ignore[operator]
            raise ValueError(f"{name}: expected an integer >= {minimum} pixels, got {value!r}")


def read_only(array: NDArray) -> NDArray:
    """Mark ``array`` read-only and return it (results are shared, never copied)."""
    array.flags.writeable = False
    return array


def read_only_copy(values: ArrayLike) -> NDArray[np.float64]:
    """A read-only float64 copy of ``values``."""
    return read_only(np.array(values, dtype=np.float64))
