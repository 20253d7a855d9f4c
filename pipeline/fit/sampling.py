"""The samples of a fit: the aperture, its pupil circle and the pixels fitted, in pupil coordinates."""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from .methods import Samples
from .results import Pupil

logger = logging.getLogger(__name__)

# A user-given pupil may cut the aperture; samples farther out than this are left out.
_PUPIL_TOLERANCE = 1e-9


def aperture_of(aperture_or_mask: Aperture | NDArray) -> Aperture:
    """The aperture itself, or the one made from a mask (non-zero = valid), shape (rows, cols)."""
    if isinstance(aperture_or_mask, Aperture):
        return aperture_or_mask
    return Aperture.from_mask(np.asarray(aperture_or_mask))


def pupil_of(aperture: Aperture, pupil: Pupil | tuple[float, float, float] | None) -> Pupil:
    """The given pupil (cx, cy, r in pixels) checked, or the aperture's minimum enclosing circle.

    Raises
    ------
    ValueError
        For a pupil that is not three finite numbers with a positive radius.
    """
    if pupil is None:
        return Pupil(*aperture.enclosing_circle())
    if not isinstance(pupil, Pupil):
        values = tuple(pupil)
        if len(values) != 3:
            raise ValueError(f"pupil: expected (cx, cy, r) in pixels, got {pupil!r}")
        pupil = Pupil(*(float(v) for v in values))
    if not (np.isfinite([pupil.cx, pupil.cy, pupil.radius]).all() and pupil.radius > 0):
        raise ValueError(f"pupil: expected finite centre and a radius > 0 pixels, got {pupil}")
    return pupil


def samples_of(
    aperture: Aperture, pupil: Pupil, user_pupil: bool, fit_mask: NDArray[np.bool_] | None
) -> Samples:
    """The fitted pixels (the fit mask's, else the aperture's) in the pupil's unit disk.

    With a user-given pupil, pixels outside it are left out and counted (``Samples.excluded``).

    Raises
    ------
    ValueError
        If no pixel is left to fit.
    """
    rows, cols = np.nonzero(aperture.mask if fit_mask is None else fit_mask)
    x = (cols - pupil.cx) / pupil.radius
    y = (pupil.cy - rows) / pupil.radius
    excluded = 0
    if user_pupil:
        inside = x * x + y * y <= 1.0 + _PUPIL_TOLERANCE
        excluded = int(inside.size - np.count_nonzero(inside))
        if excluded:
            logger.warning("%d valid pixels lie outside the given pupil and are left out", excluded)
            rows, cols, x, y = rows[inside], cols[inside], x[inside], y[inside]
    if rows.size == 0:
        raise ValueError(f"pupil: no valid pixel of the aperture lies inside {pupil}")
    flat = (rows * aperture.shape[1] + cols).astype(np.intp)
    return Samples(flat, rows, cols, x, y, excluded)


def fit_mask_of(fit_mask: NDArray | None, aperture: Aperture) -> NDArray[np.bool_] | None:
    """A fit mask checked against the aperture (same shape, one pixel at least), as booleans.

    Raises
    ------
    ValueError
        For a mask of another shape or without a non-zero pixel.
    """
    if fit_mask is None:
        return None
    fit_mask = np.asarray(fit_mask)
    if fit_mask.shape != aperture.shape:
        raise ValueError(f"fit_mask: expected shape {aperture.shape} like the aperture, got {fit_mask.shape}")
    fit_mask = fit_mask != 0
    if not fit_mask.any():
        raise ValueError("fit_mask: no pixel to fit; expected at least one non-zero pixel")
    return fit_mask
