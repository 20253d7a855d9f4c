"""The carrier's sideband in the spectrum of a fringe frame: finding it, refining it, cropping it.

The method and the crop are described in :mod:`wavestack.pipeline.phase.carrier`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray


_DETECTION_RATIO = 6.0  # sideband peak / median spectrum across it on its ring, to count as a carrier
_CENTROID_STEPS = 6  # iterations of the power-centroid refinement of the carrier
_CENTROID_FLOOR = 0.01  # power below this fraction of the sideband peak is ignored by the centroid
_CROP_REACH = 1.0  # sideband crop radius in units of |f| where no other lobe is nearer (docstring)


def _spectrum_block(
    spectrum: NDArray[np.complex64], shape: tuple[int, int], centre: tuple[int, int], half: tuple[int, int]
) -> NDArray[np.complex64]:
    """Full-spectrum values ``F[kv, ku]`` for ``kv = centre[0] + (-half[0] .. half[0])`` etc.

    ``spectrum`` is the ``rfft2`` half (non-negative ``ku``); negative ``ku`` come from the
    conjugate symmetry of a real image, ``F[kv, ku] = conj(F[-kv, -ku])``. Indices are signed bins.
    """
    rows, cols = shape
    kv = centre[0] + np.arange(-half[0], half[0] + 1)[:, None]
    ku = centre[1] + np.arange(-half[1], half[1] + 1)[None, :]
    ku_wrapped = np.mod(ku, cols)
    direct = ku_wrapped <= cols // 2
    row_index = np.where(direct, np.mod(kv, rows), np.mod(-kv, rows))
    col_index = np.where(direct, ku_wrapped, np.mod(-ku, cols))
    values = spectrum[row_index, col_index]
    return np.where(direct, values, np.conj(values))


def _crop_rho(offsets: tuple[NDArray, NDArray], carrier_rc: tuple[float, float]) -> NDArray[np.float64]:
    """Normalised distance from the carrier: 0 there, 1 on the boundary of the sideband crop.

    ``offsets`` are (row, col) frequency offsets from the carrier in cycles/px (broadcastable).
    The crop is the set of frequencies within ``_CROP_REACH * |f|`` of the carrier that are
    nearer the carrier than DC, the conjugate sideband ``-f`` and their aliases by one sampling
    frequency (a Voronoi cell of the fringe spectrum's lobes). Towards each such lobe ``c``,
    ``rho`` is the offset along ``c - f`` over half the distance ``|c - f|``.
    """
    carrier = np.array(carrier_rc, dtype=np.float64)
    rho = np.hypot(*offsets) / (_CROP_REACH * math.hypot(*carrier_rc))
    for alias in ((i, j) for i in (-1.0, 0.0, 1.0) for j in (-1.0, 0.0, 1.0)):
        for lobe in (np.array(alias), np.array(alias) - carrier):
            towards = lobe - carrier
            distance = math.hypot(*towards)
            if distance > 1e-9:  # a lobe on the carrier (an alias of f itself) is no boundary
                along = (offsets[0] * towards[0] + offsets[1] * towards[1]) / distance
                rho = np.maximum(rho, along / (0.5 * distance))
    return rho


def _crop_half(carrier_rc: tuple[float, float], shape: tuple[int, int]) -> tuple[int, int]:
    """Half sizes (rows, cols) in bins of the block holding the crop, each bin at most once."""
    reach = _CROP_REACH * math.hypot(*carrier_rc)
    return (
        max(1, min(math.ceil(reach * shape[0]), (shape[0] - 1) // 2)),
        max(1, min(math.ceil(reach * shape[1]), (shape[1] - 1) // 2)),
    )


def _find_carrier(
    spectrum: NDArray[np.complex64], shape: tuple[int, int], min_frequency: float
) -> tuple[float, float]:
    """Carrier ``(f_row, f_col)`` in cycles per pixel (row-axis frequency signed, col >= 0).

    The sideband is the highest local maximum of the 3x3-smoothed magnitude in the half-plane
    (col > 0, or col = 0 and row < 0, i.e. fy > 0) beyond ``min_frequency``. It counts as a
    carrier if it stands ``_DETECTION_RATIO`` times above the median of the smoothed magnitude on
    its own ring (same radius, +-10 %) in the sectors within 45 degrees of the perpendicular
    direction: closed fringes, noise or a smooth background fill the ring evenly and fail, a
    carrier sideband does not. The peak is then refined by the centroid of the sideband power
    within the sideband crop (:func:`_refine_carrier`).
    """
    rows, cols = shape
    dc_row = rows // 2  # row of DC once the rows are fft-shifted
    magnitude = np.fft.fftshift(np.abs(spectrum), axes=0)
    smooth = cv2.blur(magnitude, (3, 3), borderType=cv2.BORDER_REFLECT)
    local_max = smooth >= cv2.dilate(smooth, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REFLECT)
    candidate = np.where(local_max, smooth, -1.0)
    candidate[dc_row:, 0] = -1.0  # column fx = 0: keep only fy > 0 (negative row frequencies)
    reach = (math.ceil(min_frequency * rows), math.ceil(min_frequency * cols))
    box = (slice(max(dc_row - reach[0], 0), dc_row + reach[0] + 1), slice(0, reach[1] + 1))
    near_rows, near_cols = _frequencies(box, shape)
    candidate[box][np.hypot(near_rows, near_cols) < min_frequency] = -1.0
    peak_index = np.unravel_index(int(np.argmax(candidate)), candidate.shape)
    peak = ((peak_index[0] - dc_row) / rows, peak_index[1] / cols)
    peak_radius = math.hypot(*peak)
    peak_value = float(smooth[peak_index])
    # level of the spectrum on the ring through the peak, across the carrier direction
    band = max(1.5 / min(rows, cols), 0.1 * peak_radius)
    outer = peak_radius + band
    box = (
        slice(max(dc_row - math.ceil(outer * rows), 0), dc_row + math.ceil(outer * rows) + 1),
        slice(0, math.ceil(outer * cols) + 1),
    )
    box_rows, box_cols = _frequencies(box, shape)
    radius = np.hypot(box_rows, box_cols)
    along = np.abs(box_rows * peak[0] + box_cols * peak[1]) / np.maximum(radius * peak_radius, 1e-300)
    ring = (np.abs(radius - peak_radius) <= band) & (along <= math.sqrt(0.5))  # |cos| <= cos 45 deg
    level = float(np.median(smooth[box][ring])) if np.any(ring) else 0.0
    if not (peak_value > _DETECTION_RATIO * level and peak_value > 0):
        ratio = peak_value / level if level > 0 else 0.0
        raise ValueError(
            "frame: no carrier fringes found; expected tilt fringes (a sideband peak at least "
            f"{_DETECTION_RATIO:g}x the spectrum across it on its ring, beyond {min_frequency:.4g} "
            f"cycles/px); the best peak is {ratio:.3g}x, at {peak_radius:.4g} cycles/px"
        )
    noise_power = float(np.median(magnitude[box][ring].astype(np.float64) ** 2))
    return _refine_carrier(spectrum, shape, peak, noise_power)


def _frequencies(box: tuple[slice, slice], shape: tuple[int, int]) -> tuple[NDArray, NDArray]:
    """Row and column frequencies (cycles/px, broadcastable) of a box of the row-shifted spectrum."""
    rows, cols = shape
    row_index = np.arange(box[0].start, min(box[0].stop, rows))
    col_index = np.arange(box[1].start, min(box[1].stop, cols // 2 + 1))
    return ((row_index - rows // 2) / rows)[:, None], (col_index / cols)[None, :]


def _refine_carrier(
    spectrum: NDArray[np.complex64],
    shape: tuple[int, int],
    start: tuple[float, float],
    noise_power: float,
) -> tuple[float, float]:
    """Power centroid of the sideband within its crop (:func:`_crop_rho`) around the estimate.

    The centroid of ``|F|^2`` over a sideband is the carrier plus the modulation-weighted mean
    phase gradient / 2 pi; recentring the crop until it stops moving makes it symmetric about
    the estimate. The whole crop counts: a sideband spread across the carrier beyond the crop
    would leave the centroid wherever it started along that spread. A floor (the larger of the
    noise level and 1 % of the peak power) is subtracted first, so that neither noise nor the
    tail of the background spectrum reaching into the crop (strong when a bright pupil on a dark
    field is not masked) pulls the centroid.
    """
    rows, cols = shape
    estimate = (start[0] * rows, start[1] * cols)  # bins
    for _ in range(_CENTROID_STEPS):
        current = (estimate[0] / rows, estimate[1] / cols)
        half = _crop_half(current, shape)
        centre = (round(estimate[0]), round(estimate[1]))
        block = _spectrum_block(spectrum, shape, centre, half)
        dv = centre[0] + np.arange(-half[0], half[0] + 1)[:, None]
        du = centre[1] + np.arange(-half[1], half[1] + 1)[None, :]
        rho = _crop_rho(((dv - estimate[0]) / rows, (du - estimate[1]) / cols), current)
        power = np.where(rho < 1.0, np.abs(block).astype(np.float64) ** 2, 0.0)
        power -= max(noise_power, _CENTROID_FLOOR * float(power.max()))
        np.clip(power, 0.0, None, out=power)
        total = power.sum()
        if not total > 0:
            break
        updated = (float((power * dv).sum() / total), float((power * du).sum() / total))
        moved = math.hypot(updated[0] - estimate[0], updated[1] - estimate[1])
        estimate = updated
        if moved < 1e-3:
            break
    return estimate[0] / rows, estimate[1] / cols
