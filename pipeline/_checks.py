"""Checks of arguments shared by every pipeline topic: written once, raising ``ValueError``.

Three wordings are in use across the pipeline and are kept, so that messages stay what they
were; the ``voice`` parameter picks one:

* ``"must"``: ``"pitch must be > 0, got -1.0"`` (the default);
* ``"expected"``: ``"laplacian: expected one of cotangent, graph, got 'x'"`` (settings objects);
* ``"is"``: ``"open_radius_px is 0.5; expected an integer >= 0"`` (aperture detection).

Booleans are never numbers here, although Python counts them as integers.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Literal, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

Voice = Literal["must", "expected", "is"]
_T = TypeVar("_T")


def is_integer(value: object) -> bool:
    """True for Python and numpy integers, False for booleans."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def is_real(value: object) -> bool:
    """True for Python and numpy real numbers (integers included), False for booleans."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_finite_real(value: object) -> bool:
    """True for a real number (not a boolean) that is neither infinite nor NaN."""
    return is_real(value) and math.isfinite(value)  # type: ignore[arg-type]


def as_int(value: object, name: str) -> int:
    """``value`` as a Python int, or ValueError ``"<name> must be an integer, got ..."``."""
    if not is_integer(value):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return int(value)  # type: ignore[call-overload]


def int_at_least(value: object, name: str, minimum: int, *, voice: Voice = "must") -> int:
    """``value`` as an int ``>= minimum``; one message for a wrong type and a small value."""
    if not is_integer(value) or value < minimum:  # type: ignore[operator]
        if voice == "is":
            raise ValueError(f"{name} is {value!r}; expected an integer >= {minimum}")
        if voice == "expected":
            raise ValueError(f"{name}: expected an integer >= {minimum}, got {value!r}")
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)  # type: ignore[call-overload]


def positive_int(value: object, name: str) -> int:
    """``value`` as an int ``>= 1``, or ValueError naming ``name``."""
    if not is_integer(value):
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if value < 1:  # type: ignore[operator]
        raise ValueError(f"{name} must be >= 1, got {value!r}")
    return int(value)  # type: ignore[call-overload]


def finite_float(value: object, name: str) -> float:
    """``value`` as a finite float, or ValueError naming ``name``."""
    if not is_real(value):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    result = float(value)  # type: ignore[arg-type]
    if not math.isfinite(result):
        raise ValueError(f"{name} must be finite, got {result!r}")
    return result


def positive_float(value: object, name: str) -> float:
    """``value`` as a finite float ``> 0``, or ValueError naming ``name``."""
    result = finite_float(value, name)
    if result <= 0:
        raise ValueError(f"{name} must be > 0, got {result!r}")
    return result


def real_at_least(
    value: object,
    name: str,
    minimum: float,
    *,
    strict: bool = False,
    unit: str = "",
    voice: Voice = "must",
) -> float:
    """``value`` as a finite float ``>= minimum`` (``> minimum`` when ``strict``).

    Parameters
    ----------
    value : object
    name : str
        The argument's name, first word of the message.
    minimum : float
    strict : bool, optional
        Refuse ``value == minimum`` too.
    unit : str, optional
        Unit named in the message, in parentheses (``"nm"``, ``"pixels"``).
    voice : {"must", "expected", "is"}, optional
        Wording of the message (see the module docstring).

    Raises
    ------
    ValueError
        One message for a wrong type, a non-finite value and a value out of range.
    """
    if not is_finite_real(value) or not (
        value > minimum if strict else value >= minimum  # type: ignore[operator]
    ):
        wanted = f"a finite number {'>' if strict else '>='} {minimum:g}" + (f" ({unit})" if unit else "")
        if voice == "is":
            raise ValueError(f"{name} is {value!r}; expected {wanted}")
        if voice == "expected":
            raise ValueError(f"{name}: expected {wanted}, got {value!r}")
        raise ValueError(f"{name} must be {wanted}, got {value!r}")
    return float(value)  # type: ignore[arg-type]


def one_of(value: object, name: str, choices: Sequence[_T], *, voice: Voice = "must") -> _T:
    """``value`` if it is one of ``choices``, else ValueError listing them."""
    if value not in choices:
        if voice == "expected":
            listed = ", ".join(str(choice) for choice in choices)
            raise ValueError(f"{name}: expected one of {listed}, got {value!r}")
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value  # type: ignore[return-value]


def require_real_dtype(array: NDArray, name: str) -> None:
    """Refuse arrays of booleans, complex numbers or anything not an integer or float."""
    if array.dtype == np.bool_ or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise ValueError(f"{name} must be real numeric, got dtype {array.dtype}")


def real_array(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """``value`` as a float64 array, refusing booleans, complex and non-numeric data."""
    array = np.asarray(value)
    require_real_dtype(array, name)
    return np.asarray(array, dtype=np.float64)


def real_image(frame: ArrayLike, name: str) -> NDArray:
    """A 2-D real numeric array (no copy when already one), or raise ValueError."""
    image = np.asarray(frame)
    if image.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array, got shape {image.shape}")
    if image.dtype == np.bool_ or not (
        np.issubdtype(image.dtype, np.integer) or np.issubdtype(image.dtype, np.floating)
    ):
        raise ValueError(f"{name} must hold real numbers, got dtype {image.dtype}")
    return image


def optional_mask(
    mask: ArrayLike | None, shape: tuple[int, int], *, min_true: int, shape_of: str
) -> NDArray[np.bool_] | None:
    """A boolean mask of ``shape`` with at least ``min_true`` true pixels, or None.

    ``shape_of`` names what the shape must match in the message (``"that of the frame"``).
    """
    if mask is None:
        return None
    array = np.asarray(mask)
    if array.dtype != np.bool_:
        raise ValueError(f"mask: expected a boolean array, got dtype {array.dtype}")
    if array.shape != shape:
        raise ValueError(f"mask: expected shape {shape} ({shape_of}), got {array.shape}")
    if np.count_nonzero(array) < min_true:
        raise ValueError(f"mask: expected at least {min_true} true pixels")
    return array
