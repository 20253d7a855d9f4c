"""Zernike modes (n, m) and the names of the single-index orderings: what is valid, checked once."""

from __future__ import annotations

from types import MappingProxyType
from typing import Final, Literal, cast, get_args

from .._checks import as_int, one_of


Ordering = Literal["noll", "ansi", "fringe"]


_ORDERINGS: Final[tuple[str, ...]] = get_args(Ordering)
_FIRST_INDEX: Final = MappingProxyType({"noll": 1, "ansi": 0, "fringe": 1})


def validate_mode(n: int, m: int) -> tuple[int, int]:
    """Check that ``(n, m)`` names a Zernike mode and return it as Python ints.

    Parameters
    ----------
    n : int
        Radial order, ``n >= 0``.
    m : int
        Signed azimuthal frequency, ``|m| <= n`` with ``n - |m|`` even.

    Returns
    -------
    tuple of int
        ``(n, m)`` as plain Python integers.

    Raises
    ------
    ValueError
        If either value is not an integer or the pair is not a valid mode.

    References
    ----------
    Noll (1976), J. Opt. Soc. Am. 66, 207: ``R_n^m`` is defined for ``n - |m|``
    even and non-negative.
    """
    n_int = as_int(n, "n")
    m_int = as_int(m, "m")
    if n_int < 0:
        raise ValueError(f"radial order n must be >= 0, got n={n_int}")
    if abs(m_int) > n_int:
        raise ValueError(
            f"azimuthal frequency must satisfy |m| <= n, got (n, m)=({n_int}, {m_int})"
        )
    if (n_int - abs(m_int)) % 2 != 0:
        raise ValueError(f"n - |m| must be even, got (n, m)=({n_int}, {m_int})")
    return n_int, m_int


def _check_index(j: object, ordering: str) -> int:
    """Return ``j`` as an int after checking it is not below the ordering's first index."""
    j_int = as_int(j, "j")
    first = _FIRST_INDEX[ordering]
    if j_int < first:
        raise ValueError(f"{ordering} index j must be >= {first}, got j={j_int}")
    return j_int


def _check_ordering(ordering: object, name: str = "ordering") -> Ordering:
    """Return ``ordering`` if it is a known ordering name, else raise ValueError."""
    return cast(Ordering, one_of(ordering, name, _ORDERINGS))
