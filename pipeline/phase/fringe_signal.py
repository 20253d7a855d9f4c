"""The fringe signal of interferograms: where there are fringes, and whether there are any.

:func:`fringe_energy` is the aperture signal of a single carrier frame (its half-way level is the
mirror's edge); a phase-shifted set's is its modulation. :func:`check_fringe_modulation` refuses
frames that hold no phase at all (identical frames), whose "flat" map would be a fiction.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["NO_MODULATION", "check_fringe_modulation", "contrast_box", "fringe_energy"]

#: Modulation below this fraction of the frames' largest value is none: identical frames give
#: about 1e-15 (rounding), while one count of an 8-bit camera is 4e-3 of full scale.
NO_MODULATION = 1e-6


def fringe_energy(frame: NDArray, period_px: float) -> NDArray[np.float32]:
    """Local fringe energy: the squared deviation from the background, smoothed over a quarter period.

    ``E = G_(P/4) * (I - B)**2`` with ``B`` the frame's mean over a box of about two periods
    ``P`` (:func:`contrast_box`). For fringes ``B + b cos(phi)``, ``(I - B)**2``
    is ``b**2 / 2 (1 + cos(2 phi))``; a Gaussian of ``sigma = P / 4`` passes
    ``exp(-pi**2 / 2)``, 0.7 %, of the ``cos(2 phi)`` ripple, so ``E`` is ``b**2 / 2`` inside
    the disk and the halo's speckle energy outside, with an edge response only ~2 sigma wide
    either side of the edge and symmetric about it: the half-way level is the edge.

    Why not the box variance (the square of a local standard deviation), as before: its edge
    response is the whole box (two periods, 55 px on the bundled carrier frame), (i) so within
    half a box of the frame's border the box is cut or mirrored and reaches the disk from a halo
    strip thinner than that (14 px at the top and bottom of the bundled frame, which joined the
    aperture, enclosing radius 302.5 px), and (ii) a box straddling the edge adds the variance of
    the background step, ``f (1 - f) (A_in - A_out)**2`` (the disk is ~40 counts brighter than
    the halo there: up to ~400 against a half-way level of ~1100), which moves the half-way
    crossing outwards (the fitted circle came out 2.3 % wider than the cycles'). Here the
    background step leaves ``((1 - f) dA)**2`` at a pixel a fraction ``f`` of whose box is on its
    own side, the same at equal distances either side of the edge, which keeps the crossing
    there to first order. A choice made here, not a source's: the Gaussian width trades
    ripple (wider is smoother) against the edge response (narrower is sharper).

    Parameters
    ----------
    frame : ndarray, shape (rows, cols)
        Carrier interferogram, counts.
    period_px : float
        The carrier's fringe period, pixels (sets the box and the Gaussian).

    Returns
    -------
    ndarray of float32, shape (rows, cols)
        Fringe energy ``E``, counts squared.
    """
    values = np.asarray(frame, dtype=np.float32)
    size = contrast_box(period_px)
    background = cv2.boxFilter(values, cv2.CV_32F, (size, size), borderType=cv2.BORDER_REFLECT)
    cv2.subtract(values, background, dst=background)
    cv2.multiply(background, background, dst=background)
    return cv2.GaussianBlur(background, (0, 0), period_px / 4.0, borderType=cv2.BORDER_REFLECT)


def contrast_box(period_px: float) -> int:
    """Side of the background box of :func:`fringe_energy`, pixels: about two periods, odd, at least 3.

    Example
    -------
    >>> contrast_box(12.0)
    25
    """
    return max(3, int(round(2 * period_px)) | 1)


def check_fringe_modulation(modulation: NDArray, mask: NDArray[np.bool_] | None, level: float) -> None:
    """Refuse frames without fringe modulation (everywhere, or in the median over ``mask``).

    Parameters
    ----------
    modulation : ndarray, shape (rows, cols)
        Fringe modulation of a phase-shifted set, intensity units.
    mask : ndarray of bool, shape (rows, cols), optional
        The aperture; None looks at the largest modulation anywhere.
    level : float
        The frames' largest absolute value, intensity units.

    Raises
    ------
    ValueError
        If the modulation is at most ``NO_MODULATION`` times ``level`` (the frames' largest
        value): identical frames hold no phase, and their "flat" map would be a fiction.
    """
    values = np.asarray(modulation, dtype=np.float64)
    where = "" if mask is None else " in the aperture (median)"
    found = float(np.nanmax(values)) if mask is None else float(np.nanmedian(values[mask]))
    if not found > NO_MODULATION * level:
        raise ValueError(f"the frames show no fringe modulation{where} ({found:.3g} against frame values up to "
                         f"{level:.3g}); expected phase-shifted fringes, not identical frames")
