"""Checks of the arrays every dwell-time function takes, written once, raising ``ValueError``.

Each message names the argument and what was expected, so a caller (the polishing loop) can say
which of its inputs was wrong.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import real_image


def clear_aperture_mask(clear_aperture: ArrayLike, shape: tuple[int, ...] | None = None) -> NDArray[np.bool_]:
    """``clear_aperture`` as a 2-D boolean array with at least one true pixel.

    Parameters
    ----------
    clear_aperture : array_like of bool, shape (H, W)
    shape : tuple of int, optional
        The shape it must have (that of the surface), when given.

    Raises
    ------
    ValueError
        Naming ``clear_aperture``: not boolean, not 2-D, of the wrong shape, or empty.
    """
    mask = np.asarray(clear_aperture)
    if mask.dtype != np.bool_:
        raise ValueError(f"clear_aperture: expected a boolean array, got dtype {mask.dtype}")
    if mask.ndim != 2:
        raise ValueError(f"clear_aperture: expected a 2-D array, got shape {mask.shape}")
    if shape is not None and mask.shape != shape:
        raise ValueError(f"clear_aperture: expected shape {shape} (that of surface_nm), got {mask.shape}")
    if not mask.any():
        raise ValueError("clear_aperture: expected at least one true pixel, got an empty aperture")
    return mask


def surface_in_aperture(
    surface_nm: ArrayLike, clear_aperture: ArrayLike, name: str = "surface_nm"
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The surface as float64 (H, W) and its clear aperture, checked against each other.

    Values outside the clear aperture are not looked at (NaN is expected there).

    Raises
    ------
    ValueError
        Naming ``name`` (not a 2-D real array, or NaN/inf inside the clear aperture) or
        ``clear_aperture`` (see :func:`clear_aperture_mask`).
    """
    surface = np.asarray(real_image(surface_nm, name), dtype=np.float64)
    mask = clear_aperture_mask(clear_aperture, surface.shape)
    bad = np.count_nonzero(~np.isfinite(surface[mask]))
    if bad:
        raise ValueError(f"{name}: expected finite values inside the clear aperture, got {bad} NaN or inf pixels")
    return surface, mask


def read_only(array: NDArray) -> NDArray:
    """A read-only copy of ``array`` (values held by frozen results are never mutated)."""
    copy = np.array(array, copy=True)
    copy.flags.writeable = False
    return copy
