"""Index conventions for Zernike polynomials: Noll, ANSI/OSA and Fringe orderings.

Every mode is named by the pair ``(n, m)``: ``n`` is the radial order and ``m`` the
signed azimuthal frequency.  ``m > 0`` selects ``cos(m*theta)``, ``m < 0`` selects
``sin(|m|*theta)`` and ``m = 0`` is rotationally symmetric.  Angles are measured from
+x, counter-clockwise.  A pair is valid when ``n >= 0``, ``|m| <= n`` and ``n - |m|``
is even.

The three single-index orderings are

* ``"noll"``   -- Noll (1976), indices from 1, unit-RMS normalisation by default;
* ``"ansi"``   -- ANSI/OSA Z80.28 (Thibos et al. 2002), indices from 0, unit RMS;
* ``"fringe"`` -- Fringe / University of Arizona (Wyant & Creath 1992), indices from 1,
  unit value at the edge by default.

References
----------
.. [1] R. J. Noll, "Zernike polynomials and atmospheric turbulence",
   J. Opt. Soc. Am. 66, 207-211 (1976).
.. [2] L. N. Thibos, R. A. Applegate, J. T. Schwiegerling, R. Webb, "Standards for
   reporting the optical aberrations of eyes", J. Refract. Surg. 18, S652-S660 (2002);
   ANSI Z80.28-2004.
.. [3] J. C. Wyant, K. Creath, "Basic wavefront aberration theory for optical
   metrology", Applied Optics and Optical Engineering XI, ch. 1 (1992).
"""

from __future__ import annotations

import math
from typing import Final

from .._checks import as_int
from .modes import _FIRST_INDEX, _check_index, _check_ordering, Ordering, validate_mode


# Fringe index 37 is the (12, 0) term; see ``fringe_to_nm`` for the extension past 37.
_FRINGE_SPECIAL_INDEX: Final[int] = 37
_FRINGE_SPECIAL_MODE: Final[tuple[int, int]] = (12, 0)
_FRINGE_SPECIAL_GROUP: Final[int] = 6


# --------------------------------------------------------------------------- validation


def _triangle_row(j0: int) -> int:
    """Largest ``n`` with ``n(n+1)/2 <= j0``: the radial order owning 0-based position j0."""
    return (math.isqrt(8 * j0 + 1) - 1) // 2


# --------------------------------------------------------------------------- Noll


def noll_to_nm(j: int) -> tuple[int, int]:
    """Convert a Noll index to ``(n, m)``.

    Modes are sorted by radial order ``n``; inside an order by ``|m|`` ascending.
    The pair ``+|m|, -|m|`` shares two consecutive indices: the even index is the
    cosine term (``m > 0``), the odd index the sine term (``m < 0``).

    Parameters
    ----------
    j : int
        Noll index, ``j >= 1`` (``j = 1`` is piston).

    Returns
    -------
    tuple of int
        ``(n, m)``.

    Raises
    ------
    ValueError
        If ``j`` is not an integer ``>= 1``.

    References
    ----------
    Noll (1976), J. Opt. Soc. Am. 66, 207, Table I (ordering and parity rule).

    Examples
    --------
    >>> noll_to_nm(4)  # defocus
    (2, 0)
    >>> noll_to_nm(11)  # primary spherical
    (4, 0)
    >>> nm_to_noll(*noll_to_nm(22))
    22
    """
    j = _check_index(j, "noll")
    n = _triangle_row(j - 1)
    position = j - 1 - n * (n + 1) // 2  # 0 .. n inside order n
    if n % 2 == 0:
        m_abs = 2 * ((position + 1) // 2)  # 0, 2, 2, 4, 4, ...
    else:
        m_abs = 2 * (position // 2) + 1  # 1, 1, 3, 3, ...
    if m_abs == 0:
        return n, 0
    return (n, m_abs) if j % 2 == 0 else (n, -m_abs)


def nm_to_noll(n: int, m: int) -> int:
    """Convert ``(n, m)`` to the Noll index (from 1).

    Parameters
    ----------
    n, m : int
        A valid mode (see :func:`validate_mode`).

    Returns
    -------
    int
        Noll index ``j >= 1``.

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode.

    References
    ----------
    Noll (1976), J. Opt. Soc. Am. 66, 207, Table I.
    """
    n, m = validate_mode(n, m)
    before = n * (n + 1) // 2  # number of modes of lower radial order
    if m == 0:
        return before + 1
    # The pair +|m|, -|m| sits at 1-based positions |m| and |m|+1 inside order n;
    # the even one of the two indices is the cosine term.
    candidate = before + abs(m)
    wants_even = m > 0
    return candidate if (candidate % 2 == 0) == wants_even else candidate + 1


# --------------------------------------------------------------------------- ANSI


def ansi_to_nm(j: int) -> tuple[int, int]:
    """Convert an ANSI/OSA Z80.28 index to ``(n, m)``.

    Parameters
    ----------
    j : int
        ANSI index, ``j >= 0`` (``j = 0`` is piston).

    Returns
    -------
    tuple of int
        ``(n, m)`` with ``j = (n(n+2) + m) / 2``.

    Raises
    ------
    ValueError
        If ``j`` is not an integer ``>= 0``.

    References
    ----------
    Thibos et al. (2002), J. Refract. Surg. 18, S652: ``j = (n(n+2) + m)/2`` and its
    inverse; ANSI Z80.28.
    """
    j = _check_index(j, "ansi")
    n = _triangle_row(j)
    m = 2 * (j - n * (n + 1) // 2) - n
    return n, m


def nm_to_ansi(n: int, m: int) -> int:
    """Convert ``(n, m)`` to the ANSI/OSA Z80.28 index ``j = (n(n+2) + m) / 2``.

    Parameters
    ----------
    n, m : int
        A valid mode (see :func:`validate_mode`).

    Returns
    -------
    int
        ANSI index ``j >= 0``.

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode.

    References
    ----------
    Thibos et al. (2002), J. Refract. Surg. 18, S652: ``j = (n(n+2) + m)/2``;
    ANSI Z80.28.
    """
    n, m = validate_mode(n, m)
    return (n * (n + 2) + m) // 2


# --------------------------------------------------------------------------- Fringe


def _fringe_plain_index(n: int, m: int) -> int:
    """Fringe index by the group rule alone (no special place for (12, 0))."""
    group = (n + abs(m)) // 2
    if m == 0:
        return (group + 1) ** 2  # m = 0 closes its group
    return group**2 + 2 * (group - abs(m)) + 1 + (1 if m < 0 else 0)


def _fringe_plain_mode(j: int) -> tuple[int, int]:
    """Inverse of :func:`_fringe_plain_index`."""
    group = math.isqrt(j - 1)
    offset = j - 1 - group**2  # 0 .. 2*group inside the group
    if offset == 2 * group:
        return 2 * group, 0
    m_abs = group - offset // 2
    n = 2 * group - m_abs
    return (n, m_abs) if offset % 2 == 0 else (n, -m_abs)


def fringe_to_nm(j: int) -> tuple[int, int]:
    """Convert a Fringe (University of Arizona) index to ``(n, m)``.

    Terms are grouped by ``d = (n + |m|) / 2 = 0, 1, 2, ...``; inside a group ``|m|``
    descends from ``d`` to 0, the cosine term before the sine term.  This yields the
    classical 37 terms ``1 = (0, 0)``, ``2 = (1, 1)``, ``3 = (1, -1)``, ``4 = (2, 0)``,
    ..., ``36 = (10, 0)``, and ``37 = (12, 0)``.

    Extension past 37 (this package's convention; the published list stops at 37):
    indices 38..49 continue with group ``d = 6`` in the same order but skip
    ``(12, 0)``, which already has index 37; from 50 on, groups ``d = 7, 8, ...`` follow
    the group rule unchanged.  The map is therefore a bijection between ``j >= 1``
    and all valid ``(n, m)``.

    Parameters
    ----------
    j : int
        Fringe index, ``j >= 1``.

    Returns
    -------
    tuple of int
        ``(n, m)``.

    Raises
    ------
    ValueError
        If ``j`` is not an integer ``>= 1``.

    References
    ----------
    Wyant & Creath (1992), Applied Optics and Optical Engineering XI, Table 2.
    """
    j = _check_index(j, "fringe")
    if j == _FRINGE_SPECIAL_INDEX:
        return _FRINGE_SPECIAL_MODE
    group_start = _FRINGE_SPECIAL_GROUP**2 + 1  # 37: first plain index of group 6
    group_stop = (_FRINGE_SPECIAL_GROUP + 1) ** 2  # 49: last index of group 6
    if group_start < j <= group_stop:
        return _fringe_plain_mode(j - 1)  # shifted by one to make room for 37
    return _fringe_plain_mode(j)


def nm_to_fringe(n: int, m: int) -> int:
    """Convert ``(n, m)`` to the Fringe index (from 1).

    See :func:`fringe_to_nm` for the ordering and its extension past index 37.

    Parameters
    ----------
    n, m : int
        A valid mode (see :func:`validate_mode`).

    Returns
    -------
    int
        Fringe index ``j >= 1``.

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode.

    References
    ----------
    Wyant & Creath (1992), Applied Optics and Optical Engineering XI, Table 2.
    """
    n, m = validate_mode(n, m)
    if (n, m) == _FRINGE_SPECIAL_MODE:
        return _FRINGE_SPECIAL_INDEX
    plain = _fringe_plain_index(n, m)
    if (n + abs(m)) // 2 == _FRINGE_SPECIAL_GROUP:
        return plain + 1
    return plain


# --------------------------------------------------------------------------- dispatchers


def first_index(ordering: Ordering) -> int:
    """Return the smallest index of an ordering (1 for Noll and Fringe, 0 for ANSI).

    Parameters
    ----------
    ordering : {"noll", "ansi", "fringe"}
        Index convention.

    Returns
    -------
    int
        The index of piston in that ordering.

    Raises
    ------
    ValueError
        If ``ordering`` is not one of the known names.

    References
    ----------
    Noll (1976); ANSI Z80.28; Wyant & Creath (1992).
    """
    return _FIRST_INDEX[_check_ordering(ordering)]


def index_to_nm(j: int, ordering: Ordering) -> tuple[int, int]:
    """Convert a single index in the given ordering to ``(n, m)``.

    Parameters
    ----------
    j : int
        Index, from :func:`first_index` of ``ordering`` on.
    ordering : {"noll", "ansi", "fringe"}
        Index convention.

    Returns
    -------
    tuple of int
        ``(n, m)``.

    Raises
    ------
    ValueError
        If ``ordering`` is unknown or ``j`` is out of range.

    References
    ----------
    See :func:`noll_to_nm`, :func:`ansi_to_nm`, :func:`fringe_to_nm`.

    Examples
    --------
    Index 5 is an astigmatism term in every ordering, not always the same one:

    >>> index_to_nm(5, "ansi"), index_to_nm(5, "noll"), index_to_nm(5, "fringe")
    ((2, 2), (2, -2), (2, 2))
    """
    ordering_name = _check_ordering(ordering)
    if ordering_name == "noll":
        return noll_to_nm(j)
    if ordering_name == "ansi":
        return ansi_to_nm(j)
    return fringe_to_nm(j)


def nm_to_index(n: int, m: int, ordering: Ordering) -> int:
    """Convert ``(n, m)`` to the single index of the given ordering.

    Parameters
    ----------
    n, m : int
        A valid mode.
    ordering : {"noll", "ansi", "fringe"}
        Index convention.

    Returns
    -------
    int
        Index in ``ordering``.

    Raises
    ------
    ValueError
        If ``ordering`` is unknown or ``(n, m)`` is not a valid mode.

    References
    ----------
    See :func:`nm_to_noll`, :func:`nm_to_ansi`, :func:`nm_to_fringe`.
    """
    ordering_name = _check_ordering(ordering)
    if ordering_name == "noll":
        return nm_to_noll(n, m)
    if ordering_name == "ansi":
        return nm_to_ansi(n, m)
    return nm_to_fringe(n, m)


def mode_list(ordering: Ordering, count: int) -> list[tuple[int, int]]:
    """Return the first ``count`` modes of an ordering as ``(n, m)`` pairs.

    Parameters
    ----------
    ordering : {"noll", "ansi", "fringe"}
        Index convention.
    count : int
        Number of modes, ``count >= 0``.

    Returns
    -------
    list of tuple of int
        ``[(n, m) for j = first, first + 1, ..., first + count - 1]``.

    Raises
    ------
    ValueError
        If ``ordering`` is unknown or ``count`` is not a non-negative integer.

    References
    ----------
    See :func:`index_to_nm`.
    """
    first = first_index(ordering)
    count = as_int(count, "count")
    if count < 0:
        raise ValueError(f"count must be >= 0, got count={count}")
    return [index_to_nm(first + i, ordering) for i in range(count)]
