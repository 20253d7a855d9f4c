"""Converting Zernike coefficients between orderings and normalisations."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import as_int
from .indices import first_index, mode_list, nm_to_index
from .modes import Ordering
from .normalisation import _check_normalisation, Normalisation, default_normalisation, normalisation_factor


def convert_coefficients(
    coefficients: ArrayLike,
    source: Ordering,
    target: Ordering,
    *,
    source_normalisation: Normalisation | None = None,
    target_normalisation: Normalisation | None = None,
    count: int | None = None,
) -> NDArray[np.float64]:
    """Re-express a Zernike coefficient vector in another ordering and normalisation.

    The represented surface ``sum_j c_j Z_j`` is unchanged.  With
    ``Z = N R trig``, a term ``c_s N_s R trig`` equals ``c_t N_t R trig`` for
    ``c_t = c_s N_s / N_t``; e.g. the coefficient of a unit-RMS term is the
    edge-normalised coefficient divided by ``sqrt(2(n+1)/(1+delta_m0))``.

    Parameters
    ----------
    coefficients : array_like, shape (L,)
        Real coefficients; element ``i`` belongs to index ``first_index(source) + i``.
        Units are whatever the surface is in (e.g. waves or nm).
    source, target : {"noll", "ansi", "fringe"}
        Orderings of the input and the output.
    source_normalisation, target_normalisation : {"rms", "edge"}, optional
        Default: :func:`default_normalisation` of ``source`` and ``target``.
    count : int, optional
        Length of the output.  Default: the smallest length in ``target`` that holds
        every source mode with a non-zero coefficient (0 if all are zero).  Source modes
        with a zero coefficient that do not fit are dropped silently.

    Returns
    -------
    numpy.ndarray, shape (count,)
        Coefficients in ``target`` ordering and normalisation; modes absent from the
        source are zero.

    Raises
    ------
    ValueError
        If ``coefficients`` is not a real, finite 1-D array, an ordering or
        normalisation is unknown, ``count`` is negative, or (with ``count`` given) a
        non-zero source coefficient has no place in the output; the message names the
        mode ``(n, m)`` and its source index.

    References
    ----------
    Noll (1976) (unit RMS) and Wyant & Creath (1992), Table 2 (unit edge value) for
    the two normalisations.

    Examples
    --------
    One unit-RMS wave of Noll defocus (j = 4) is sqrt(3) waves of edge-normalised Fringe
    defocus (j = 4 as well), and sits at index 4 in ANSI order (from 0):

    >>> import numpy as np
    >>> np.round(convert_coefficients([0.0, 0.0, 0.0, 1.0], "noll", "fringe"), 6)
    array([0.      , 0.      , 0.      , 1.732051])
    >>> convert_coefficients([0.0, 0.0, 0.0, 1.0], "noll", "ansi")
    array([0., 0., 0., 0., 1.])
    """
    values = np.asarray(coefficients)
    if values.ndim != 1:
        raise ValueError(f"coefficients must be a 1-D array, got shape {values.shape}")
    if not (np.issubdtype(values.dtype, np.floating) or np.issubdtype(values.dtype, np.integer)):
        raise ValueError(f"coefficients must be real numbers, got dtype {values.dtype}")
    values = values.astype(np.float64)
    if not np.all(np.isfinite(values)):
        raise ValueError("coefficients must all be finite")
    source_first = first_index(source)
    target_first = first_index(target)
    source_norm = _check_normalisation(
        default_normalisation(source) if source_normalisation is None else source_normalisation,
        "source_normalisation",
    )
    target_norm = _check_normalisation(
        default_normalisation(target) if target_normalisation is None else target_normalisation,
        "target_normalisation",
    )

    modes = mode_list(source, values.size)
    positions = [nm_to_index(n, m, target) - target_first for n, m in modes]
    if count is None:
        occupied = [p for p, value in zip(positions, values) if value != 0.0]
        length = max(occupied) + 1 if occupied else 0
    else:
        length = as_int(count, "count")
        if length < 0:
            raise ValueError(f"count must be >= 0, got count={length}")

    result = np.zeros(length, dtype=np.float64)
    for i, ((n, m), position, value) in enumerate(zip(modes, positions, values)):
        if position >= length:
            if value != 0.0:
                raise ValueError(
                    f"count={length} has no place for mode (n, m)=({n}, {m}) with non-zero "
                    f"coefficient at {source} index {source_first + i}; it needs "
                    f"count >= {position + 1} in {target} ordering"
                )
            continue
        ratio = normalisation_factor(n, m, source_norm) / normalisation_factor(n, m, target_norm)
        result[position] = value * ratio
    return result
