"""Removal from a dwell map, and the residual it leaves in the clear aperture.

Removal = TIF convolved with the dwell-time map (Preston's law; Jones, Appl. Opt. 16, 218, 1977).
The convolution is linear (zero-padded, ``scipy.signal.fftconvolve`` mode ``"same"``), not
circular: with the kernel odd-sized and centred, ``"same"`` puts removal exactly where the tool
dwelt, and dwell near one border never wraps round to the other.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import fftconvolve

from .._checks import real_image
from ._inputs import surface_in_aperture
from .tif import ToolInfluence


def removal_nm(dwell_s: ArrayLike, tif: ToolInfluence) -> NDArray[np.float64]:
    """Material removed (nm) by dwelling ``dwell_s`` seconds per pixel with tool ``tif``.

    Parameters
    ----------
    dwell_s : array_like, shape (H, W)
        Dwell time at each pixel (s), finite.
    tif : ToolInfluence
        The tool, on the same pixel grid.

    Returns
    -------
    NDArray[np.float64], shape (H, W)
        ``removal[p] = sum_q dwell[q] * kernel[p - q + r]`` (nm), dwell outside the array
        taken as zero.

    Raises
    ------
    ValueError
        Naming ``dwell_s`` when it is not a finite 2-D real array.

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline.polishing import ToolInfluence, removal_nm
    >>> tif = ToolInfluence.gaussian(fwhm_mm=1.0, peak_rate_nm_s=5.0, pixel_mm=0.25)
    >>> dwell = np.zeros((21, 21)); dwell[10, 10] = 2.0
    >>> removed = removal_nm(dwell, tif)
    >>> float(removed[10, 10]), bool(np.allclose(removed.sum(), 2.0 * tif.kernel_nm_per_s.sum()))
    (10.0, True)
    """
    dwell = np.asarray(real_image(dwell_s, "dwell_s"), dtype=np.float64)
    if not np.all(np.isfinite(dwell)):
        raise ValueError("dwell_s: expected finite dwell times, got NaN or inf")
    removed = fftconvolve(dwell, tif.kernel_nm_per_s, mode="same")
    return np.asarray(removed, dtype=np.float64)


def residual_after(
    surface_nm: ArrayLike, clear_aperture: ArrayLike, removal: ArrayLike
) -> tuple[NDArray[np.float64], float, float]:
    """The surface left after ``removal``, in the clear aperture, piston removed.

    Removal lowers the surface (heights are surface height, removal positive down), so the
    residual is ``surface - removal``; a uniform layer costs nothing in figure, so its mean over
    the clear aperture is subtracted.

    Parameters
    ----------
    surface_nm : array_like, shape (H, W)
        Surface height error (nm); finite inside the clear aperture (NaN allowed outside).
    clear_aperture : array_like of bool, shape (H, W)
        The pixels the figure is judged on; not empty.
    removal : array_like, shape (H, W)
        Predicted (or measured) removal (nm); finite inside the clear aperture.

    Returns
    -------
    residual_nm : NDArray[np.float64], shape (H, W)
        ``surface - removal`` minus its clear-aperture mean; NaN outside the clear aperture.
    rms_nm : float
        Root mean square of the residual over the clear aperture (piston removed).
    pv_nm : float
        Peak to valley of the residual over the clear aperture.

    Raises
    ------
    ValueError
        Naming ``surface_nm``, ``clear_aperture`` or ``removal`` (shape, NaN inside, empty).
    """
    surface, mask = surface_in_aperture(surface_nm, clear_aperture)
    removed = np.asarray(real_image(removal, "removal"), dtype=np.float64)
    if removed.shape != surface.shape:
        raise ValueError(f"removal: expected shape {surface.shape} (that of surface_nm), got {removed.shape}")
    if not np.all(np.isfinite(removed[mask])):
        raise ValueError("removal: expected finite values inside the clear aperture, got NaN or inf")
    inside = surface[mask] - removed[mask]
    inside = inside - inside.mean()
    residual = np.full(surface.shape, np.nan)
    residual[mask] = inside
    return residual, float(np.sqrt(np.mean(inside**2))), float(inside.max() - inside.min())
