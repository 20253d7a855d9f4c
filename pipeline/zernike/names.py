"""Names of the low-order Zernike modes, in the words opticians use ("primary spherical")."""

from __future__ import annotations

from types import MappingProxyType
from typing import Final

from .modes import validate_mode


_MODE_NAMES: Final = MappingProxyType(
    {
        (0, 0): "piston",
        (1, 1): "tilt x",
        (1, -1): "tilt y",
        (2, 0): "defocus",
        (2, 2): "astigmatism 0/90",
        (2, -2): "astigmatism 45",
        (3, 1): "coma x",
        (3, -1): "coma y",
        (3, 3): "trefoil x",
        (3, -3): "trefoil y",
        (4, 0): "primary spherical",
        (4, 2): "secondary astigmatism 0/90",
        (4, -2): "secondary astigmatism 45",
        (4, 4): "tetrafoil 0",
        (4, -4): "tetrafoil 22.5",
        (5, 1): "secondary coma x",
        (5, -1): "secondary coma y",
        (6, 0): "secondary spherical",
    }
)


def mode_name(n: int, m: int) -> str:
    """Return the classical aberration name of a low-order mode.

    Parameters
    ----------
    n, m : int
        A valid mode.

    Returns
    -------
    str
        E.g. ``"defocus"`` for ``(2, 0)`` or ``"coma y"`` for ``(3, -1)``; modes without a
        classical name get the generic ``"Z(n,m)"``.

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode.

    References
    ----------
    Wyant & Creath (1992), Table 2; Noll (1976), Table I.

    Examples
    --------
    >>> mode_name(4, 0)
    'primary spherical'
    """
    n, m = validate_mode(n, m)
    return _MODE_NAMES.get((n, m), f"Z({n},{m})")
