"""Argument checks shared by the drivers: numbers, integers in a wire range, timeouts, read-only arrays.

The predicates return a bool and leave the error message to the caller, whose wording names the
device field (tests match on it); :func:`check_timeout` raises its own, one wording for every
driver that uses it. The simulators keep their own checks (:mod:`wavestack.simulators._checks`):
a simulator never imports the driver.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["check_timeout", "is_finite_real", "is_integral_in", "is_number", "read_only_copy"]


def is_number(value: object) -> bool:
    """True for a Python or numpy int or float, False for a bool or anything else."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def is_finite_real(value: object) -> bool:
    """True for a finite Python int or float (numpy ``float64`` is a float), False for a bool."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def is_integral_in(value: object, low: int, high: int) -> bool:
    """True if ``value`` equals an integer in ``[low, high]`` (``3.0`` does), False for a bool.

    Raises
    ------
    TypeError, ValueError
        From ``int(value)`` when ``value`` is no number at all (None, a string, NaN), as the
        register codecs always raised.
    """
    if isinstance(value, bool):
        return False
    as_int = int(value)  # type: ignore[call-overload]
    return as_int == value and low <= as_int <= high


def check_timeout(timeout_s: float) -> None:
    """ValueError unless ``timeout_s`` (seconds) is finite and ``> 0``."""
    if not (math.isfinite(timeout_s) and timeout_s > 0):
        raise ValueError(f"timeout_s must be a finite number > 0, got {timeout_s}")


def read_only_copy(values: ArrayLike) -> NDArray[np.float64]:
    """A read-only float64 copy of ``values``."""
    out = np.array(values, dtype=np.float64)
    out.setflags(write=False)
    return out
