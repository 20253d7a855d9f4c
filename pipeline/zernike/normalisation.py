"""Zernike normalisations: unit RMS over the disk or unit value at the edge, and the default of each
ordering.
"""

from __future__ import annotations

import math
from typing import Final, Literal, cast, get_args

from .._checks import one_of
from .modes import _check_ordering, Ordering, validate_mode


Normalisation = Literal["rms", "edge"]


_NORMALISATIONS: Final[tuple[str, ...]] = get_args(Normalisation)


def _check_normalisation(normalisation: object, name: str = "normalisation") -> Normalisation:
    """Return ``normalisation`` if it is a known name, else raise ValueError."""
    return cast(Normalisation, one_of(normalisation, name, _NORMALISATIONS))


def default_normalisation(ordering: Ordering) -> Normalisation:
    """Return the customary normalisation of an ordering.

    Parameters
    ----------
    ordering : {"noll", "ansi", "fringe"}
        Index convention.

    Returns
    -------
    {"rms", "edge"}
        ``"rms"`` for Noll and ANSI, ``"edge"`` for Fringe.

    Raises
    ------
    ValueError
        If ``ordering`` is unknown.

    References
    ----------
    Noll (1976) and ANSI Z80.28 use unit RMS; Wyant & Creath (1992) use unit
    value at the edge of the pupil.
    """
    return "edge" if _check_ordering(ordering) == "fringe" else "rms"


def normalisation_factor(n: int, m: int, normalisation: Normalisation) -> float:
    """Return the factor ``N`` in ``Z = N * R_n^|m|(rho) * trig(m*theta)``.

    Parameters
    ----------
    n, m : int
        A valid mode.
    normalisation : {"rms", "edge"}
        ``"rms"``: unit RMS over the unit disk, ``N = sqrt(2(n+1) / (1 + delta_m0))``.
        ``"edge"``: ``N = 1``, so cosine and ``m = 0`` terms equal 1 at ``rho = 1,
        theta = 0``.

    Returns
    -------
    float
        The factor ``N`` (dimensionless).

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode or ``normalisation`` is unknown.

    References
    ----------
    Noll (1976), J. Opt. Soc. Am. 66, 207: ``Z_j = sqrt(n+1) R_n^m`` for ``m = 0`` and
    ``sqrt(2(n+1)) R_n^m cos/sin(m theta)`` otherwise (unit RMS).
    """
    n, m = validate_mode(n, m)
    if _check_normalisation(normalisation) == "edge":
        return 1.0
    return math.sqrt(2.0 * (n + 1) / (2.0 if m == 0 else 1.0))
