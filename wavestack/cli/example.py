"""The bundled synthetic example: a known wavefront on an off-axis mirror's aperture.

Until the simulated station exists, ``wavestack fit --example`` fits this map so that a fresh
install shows the whole fit path end to end and how close it comes to a known truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.bench.paper_apertures import rounded_rectangle_mask
from wavestack.pipeline import noll_to_nm, zernike_basis

# A 3.5:1 rounded rectangle, the shape of a mirror in an off-axis three-mirror anastigmat.
_ROWS, _COLS = 160, 480
_HALF_LENGTH, _HALF_WIDTH, _CORNER = 210.0, 60.0, 20.0
# Truth: a few Noll terms (unit RMS over the circumscribed circle), in waves.
_TRUTH_NOLL = {4: 0.020, 5: -0.012, 6: 0.006, 7: 0.004, 8: -0.003, 11: 0.0025, 22: -0.001}
_NOISE_RMS_WAVES = 0.002


@dataclass(frozen=True)
class SyntheticExample:
    """A wavefront map with its known truth.

    Attributes
    ----------
    wavefront : ndarray, shape (rows, cols)
        Truth plus white noise, in waves; NaN outside the aperture.
    truth : ndarray, shape (rows, cols)
        The noise-free wavefront, NaN outside the aperture.
    mask : ndarray of bool, shape (rows, cols)
    noise_rms : float
        Standard deviation of the added noise, in waves.
    description : str
    """

    wavefront: NDArray[np.float64]
    truth: NDArray[np.float64]
    mask: NDArray[np.bool_]
    noise_rms: float
    description: str


def synthetic_example(seed: int = 20261122) -> SyntheticExample:
    """Build the example: a Zernike wavefront with white noise on a 3.5:1 rounded rectangle.

    The truth is a combination of Noll terms over the rectangle's circumscribed circle; the
    noise is seeded, so the example is the same on every machine.
    """
    mask = rounded_rectangle_mask((_ROWS, _COLS), _HALF_LENGTH, _HALF_WIDTH, _CORNER)
    rows, cols = np.nonzero(mask)
    centre_row, centre_col = (_ROWS - 1) / 2, (_COLS - 1) / 2
    radius = float(np.hypot(_HALF_LENGTH, _HALF_WIDTH))
    x, y = (cols - centre_col) / radius, (centre_row - rows) / radius
    modes = [noll_to_nm(j) for j in _TRUTH_NOLL]
    values = zernike_basis(modes, x, y) @ np.array(list(_TRUTH_NOLL.values()))
    truth = np.full(mask.shape, np.nan)
    truth[rows, cols] = values
    noise = np.random.default_rng(seed).normal(0.0, _NOISE_RMS_WAVES, values.size)
    wavefront = truth.copy()
    wavefront[rows, cols] += noise
    return SyntheticExample(
        wavefront=wavefront,
        truth=truth,
        mask=mask,
        noise_rms=_NOISE_RMS_WAVES,
        description=(
            f"synthetic example: {_ROWS} x {_COLS} map, 3.5:1 rounded rectangle, "
            f"{len(modes)} Zernike terms plus {_NOISE_RMS_WAVES} waves RMS white noise"
        ),
    )
