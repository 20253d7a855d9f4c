"""Mid-spatial roughness of the simulated optic: a seeded Gaussian random field.

White noise filtered by a Gaussian in Fourier space gives a stationary Gaussian field whose
autocorrelation is Gaussian, ``C(r) = sigma^2 exp(-r^2 / l^2)``: the correlation length ``l`` is
the lag where the autocorrelation falls to ``1/e`` (the usual definition for random rough
surfaces, Ogilvy 1991, ch. 2). Filtering unit white noise with the transfer function
``T(f) = exp(-pi^2 l^2 |f|^2 / 2)`` gives the power spectrum ``|T|^2 = exp(-pi^2 l^2 |f|^2)``,
the Fourier transform of that autocorrelation (Wiener-Khinchin).

The noise is drawn on a grid larger than the frame by up to three correlation lengths and the
frame cut from it, so the FFT's periodic wrap does not correlate opposite edges (at ``3 l`` the
autocorrelation is ``exp(-9) = 1.2e-4``). The field is then made piston-free and scaled to the
requested RMS over the aperture exactly (this realisation's RMS, not the ensemble's).

References
----------
.. [1] J. A. Ogilvy, *Theory of Wave Scattering from Random Rough Surfaces*, Adam Hilger (1991),
   ch. 2 (height statistics, Gaussian autocorrelation and correlation length).
.. [2] J. W. Goodman, *Statistical Optics*, 2nd ed., Wiley (2015), sec. 3.4 (filtered white noise
   and its power spectrum).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from wavestack.simulators._checks import check_seed, finite_number

__all__ = ["gaussian_random_field"]


def gaussian_random_field(
    mask: NDArray[np.bool_], *, rms_nm: float, correlation_px: float, seed: int
) -> NDArray[np.float64]:
    """A Gaussian random field on the grid of ``mask``, piston-free with RMS ``rms_nm`` over it.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
        The aperture: where the piston is removed and the RMS is set. The field covers the
        whole grid.
    rms_nm : float
        RMS over the aperture, nm, ``>= 0`` (0 gives zeros).
    correlation_px : float
        Correlation length, pixels, ``> 0`` (module notes).
    seed : int
        Seed of the white noise, ``>= 0``: the same seed gives the same field.

    Returns
    -------
    ndarray of float64, shape (H, W)
        The field, nm. Zeros when ``rms_nm`` is 0 or the aperture has fewer than two pixels.

    Raises
    ------
    ValueError
        If an argument is out of range (the message names it).

    Examples
    --------
    >>> mask = np.ones((64, 64), dtype=bool)
    >>> field = gaussian_random_field(mask, rms_nm=3.0, correlation_px=4.0, seed=1)
    >>> round(float(np.sqrt(np.mean(field ** 2))), 6), round(abs(float(field.mean())), 9)
    (3.0, 0.0)
    """
    rms = finite_number(rms_nm, "rms_nm", minimum=0.0)
    length = finite_number(correlation_px, "correlation_px", above=0.0)
    check_seed(seed)
    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f"mask: expected a 2-D array, got shape {mask.shape}")
    height, width = mask.shape
    if rms == 0 or np.count_nonzero(mask) < 2:
        return np.zeros((height, width))
    pad = int(min(math.ceil(3.0 * length), max(height, width)))  # beyond the frame's size, wrap no longer matters
    rows, cols = scipy.fft.next_fast_len(height + pad, real=True), scipy.fft.next_fast_len(width + pad, real=True)
    noise = np.random.default_rng(seed).standard_normal((rows, cols))
    fy = np.fft.fftfreq(rows)[:, None]
    fx = np.fft.rfftfreq(cols)[None, :]
    transfer = np.exp(-0.5 * (math.pi * length) ** 2 * (fx**2 + fy**2))
    field = scipy.fft.irfft2(scipy.fft.rfft2(noise) * transfer, s=(rows, cols))[:height, :width]
    field = field - field[mask].mean()
    spread = math.sqrt(float(np.mean(field[mask] ** 2)))
    if spread == 0.0:
        return np.zeros((height, width))
    return field * (rms / spread)
