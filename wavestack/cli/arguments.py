"""Argument types shared by the subcommands (argparse ``type=`` callables)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def positive_int(text: str) -> int:
    """A positive integer, or argparse's usage error naming the bad value."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """A number > 0 (e.g. seconds), or argparse's usage error naming the bad value."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """A finite number (no nan, no inf), or argparse's usage error naming the bad value."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_finite_float(text: str) -> float:
    """A finite number > 0 (e.g. millimetres), or argparse's usage error naming the bad value."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def unit_fraction(text: str) -> float:
    """A fraction from 0 to 1 inclusive, or argparse's usage error naming the bad value."""
    value = finite_float(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a fraction from 0 to 1, got {text!r}")
    return value


def obscuration_ratio(text: str) -> float:
    """An obscuration ratio (inner over outer radius) strictly between 0 and 1, or argparse's usage error."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"expected a ratio of inner to outer radius between 0 and 1, got {text!r}")
    return value


# An interferometer's wavelength lies in (1 nm, 1 mm): X-rays to the far infrared.
WAVELENGTH_RANGE_NM = (1.0, 1e6)


def wavelength_nm(text: str) -> float:
    """A wavelength in nanometres within :data:`WAVELENGTH_RANGE_NM`, or argparse's usage error."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    low, high = WAVELENGTH_RANGE_NM
    if not low < value < high:
        raise argparse.ArgumentTypeError(f"expected a wavelength in nm between {low:g} and {high:g}, got {text!r}")
    return value


def bounded_int(maximum: int, why: str) -> Callable[[str], int]:
    """An argparse type: an integer from 1 to ``maximum``; ``why`` says where the bound comes from."""
    def parse(text: str) -> int:
        value = positive_int(text)
        if value > maximum:
            raise argparse.ArgumentTypeError(f"expected at most {maximum} ({why}), got {text!r}")
        return value
    return parse
