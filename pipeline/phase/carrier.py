"""Single-frame phase from carrier (tilt) fringes: the Fourier-transform method.

Sign convention (project-wide, as in :mod:`wavestack.pipeline.phase.psi.algorithms`)
------------------------------------------------------------------
A frame with carrier fringes is modelled as

    I(x, y) = A + B cos(phi(x, y) + 2 pi (fx x + fy y)),

with pixel coordinates x = col and y = -row (y points up) and the carrier ``f = (fx, fy)`` in
cycles per pixel. The method returns ``phi`` with the carrier removed, in radians wrapped to
(-pi, pi]; a positive ``phi`` is a positive wavefront (waves = ``phi / (2 pi)``), the same
``phi`` that phase-shifting frames ``A + B cos(phi + delta_k)`` give with ``delta_k = +k step``.

Which sideband is "+f"
----------------------
The spectrum of a real frame holds two conjugate sidebands, ``(B/2) e^{+i phi}`` at ``+f`` and
``(B/2) e^{-i phi}`` at ``-f``; the model is unchanged by ``(phi, f) -> (-phi, -f)``. A single
carrier frame therefore cannot tell ``phi`` from ``-phi`` unless the direction of the tilt is
known. The sideband taken as ``+f`` is the one in the half-plane ``fx > 0``, or ``fy > 0`` when
``fx = 0``. If the tilt of the setup points the other way, pass ``sign=-1``: the phase is negated
and the reported carrier is ``-f``. Passing an explicit ``carrier`` selects the sideband at
exactly that frequency (either half-plane); ``sign`` is applied on top of it.

Algorithm
---------
Subtract a smooth background (a Gaussian low-pass at half the longest fringe period searched
for, computed inside the mask when one is given), taper the frame (or the mask) edge smoothly to
zero, take the real FFT, find the highest local peak beyond a minimum radius in the half-plane
above, check that it stands clearly above the spectrum on its ring, refine it to a small
fraction of a bin by the power centroid of the sideband, crop the sideband (below), shift it to
DC (integer part of the carrier) and inverse-transform only that crop: along y for its few
non-zero spectral columns, then along x zero-padded to full size (exact band-limited
interpolation); the sub-bin remainder of the carrier is removed by a conjugate ramp.

The sideband crop
-----------------
The only other lobes of ``A + B cos(...)`` are the background at DC and the conjugate sideband
at ``-f`` (and their aliases one sampling frequency away). The crop takes every frequency that
is nearer the carrier than any of them, up to ``|f|`` from the carrier: towards DC it stops
half-way (``|f| / 2``, the classical limit, below which a sideband cannot be told from the
background), across the fringes and away from DC it reaches ``|f|``. A circle of radius
``|f| / 2`` would be needlessly narrow there: the local fringe frequency of a wavefront with a
few waves of defocus or astigmatism moves across the carrier by more than ``|f| / 2`` on small
frames (about 35 fringes on 256 px), and the part of the sideband cut off leaves near-zero
modulation, phase singularities and unwrapping errors that take the low orders with them. The
window is applied in the normalised distance ``rho`` (0 at the carrier, 1 on the crop boundary:
the larger of ``|k - f| / |f|`` and, for each other lobe ``c``, the offset towards ``c``
over half the distance to it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import cv2
import numpy as np
import scipy.fft
import scipy.special
from numpy.typing import ArrayLike, NDArray

_WINDOWS = ("hann", "tukey", "rect")
_TAPER_SIGMA = 2.0  # px: Gaussian softening of the frame / mask edge before the FFT
_DETECTION_RATIO = 6.0  # sideband peak / median spectrum across it on its ring, to count as a carrier
_MIN_RELATIVE_RMS = 1e-5  # background-removed frame RMS / max |frame| below which there are no fringes
_CENTROID_STEPS = 6  # iterations of the power-centroid refinement of the carrier
_CENTROID_FLOOR = 0.01  # power below this fraction of the sideband peak is ignored by the centroid
_MIN_SIDE = 16  # px: smallest frame side accepted
_CROP_REACH = 1.0  # sideband crop radius in units of |f| where no other lobe is nearer (docstring)


@dataclass(frozen=True, eq=False)
class CarrierResult:
    """Phase recovered from one frame with carrier fringes.

    Attributes
    ----------
    phase : ndarray of float32, shape (rows, cols)
        Wrapped ``phi`` with the carrier removed, radians in (-pi, pi]; sign convention in the
        module docstring. Meaningless where ``modulation`` is ~0 (outside the mask or fringes).
    modulation : ndarray of float32, shape (rows, cols)
        ``2 |sideband|``: the fringe amplitude ``B`` in intensity units (lowered near the
        tapered edges of the frame or mask, and by the window where the local fringe frequency
        is far from the carrier), directly comparable to the PSI modulation.
    carrier : tuple of float
        ``(fx, fy)`` in cycles per pixel, x = col and y = -row (y up).
    window : str
        The spectral window used around the sideband.
    """

    phase: NDArray[np.float32]
    modulation: NDArray[np.float32]
    carrier: tuple[float, float]
    window: str


# ----------------------------------------------------------------------------- validation


def _check_frame(frame: ArrayLike) -> NDArray:
    array = np.asarray(frame)
    if array.ndim != 2:
        raise ValueError(f"frame: expected a 2-D intensity image, got shape {array.shape}")
    if min(array.shape) < _MIN_SIDE:
        raise ValueError(f"frame: expected at least {_MIN_SIDE}x{_MIN_SIDE} pixels, got {array.shape}")
    if array.dtype.kind not in "iuf":
        raise ValueError(f"frame: expected real numbers (integer or float), got dtype {array.dtype}")
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise ValueError("frame: expected finite values, found NaN or infinity")
    return array


def _check_mask(mask: ArrayLike | None, shape: tuple[int, int]) -> NDArray[np.bool_] | None:
    if mask is None:
        return None
    array = np.asarray(mask)
    if array.dtype != np.bool_:
        raise ValueError(f"mask: expected a boolean array, got dtype {array.dtype}")
    if array.shape != shape:
        raise ValueError(f"mask: expected shape {shape} (that of the frame), got {array.shape}")
    if np.count_nonzero(array) < _MIN_SIDE * _MIN_SIDE:
        raise ValueError(f"mask: expected at least {_MIN_SIDE * _MIN_SIDE} true pixels")
    return array


def _check_carrier(carrier: ArrayLike, shape: tuple[int, int]) -> tuple[float, float]:
    try:
        values = np.asarray(carrier, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("carrier: expected (fx, fy) in cycles per pixel") from None
    if values.shape != (2,) or not np.isfinite(values).all():
        raise ValueError(f"carrier: expected two finite numbers (fx, fy) in cycles per pixel, got {carrier!r}")
    fx, fy = (float(v) for v in values)
    if max(abs(fx), abs(fy)) >= 0.5:
        raise ValueError(f"carrier: expected |fx|, |fy| < 0.5 cycles per pixel (Nyquist), got {(fx, fy)}")
    if math.hypot(fx, fy) * min(shape) < 4.0:
        raise ValueError(
            f"carrier: expected at least 4 fringes across the frame (|f| >= {4.0 / min(shape):.4g} "
            f"cycles per pixel), got {(fx, fy)}"
        )
    return fx, fy


# ----------------------------------------------------------------------------- spectrum helpers


def _taper(mask: NDArray[np.bool_] | None, shape: tuple[int, int]) -> NDArray[np.float32]:
    """Weights in [0, 1]: 1 inside, falling smoothly to 0 at the mask (or frame) edge."""
    if mask is None:  # separable: the product of the two 1-D edge ramps
        return _edge_ramp(shape[0])[:, None] * _edge_ramp(shape[1])[None, :]
    blurred = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), _TAPER_SIGMA, borderType=cv2.BORDER_CONSTANT)
    weights = 2.0 * blurred - 1.0
    np.clip(weights, 0.0, 1.0, out=weights)
    return weights


def _background(values: NDArray[np.float32], mask: NDArray[np.bool_] | None, sigma: float) -> NDArray[np.float32]:
    """Smooth background: Gaussian low-pass of ``sigma`` px (inside the mask, normalised convolution).

    Computed on a grid reduced about ``sigma / 4`` times and interpolated back, so its cost does
    not grow with ``sigma``. With ``sigma`` half the longest fringe period searched for, the
    fringes themselves pass below 1 %.
    """
    rows, cols = values.shape
    factor = max(1, int(sigma // 4))
    reduced = (max(1, round(cols / factor)), max(1, round(rows / factor)))  # cv2 order: (width, height)
    scaled_sigma = sigma * reduced[0] / cols
    if mask is None:
        small = cv2.resize(values, reduced, interpolation=cv2.INTER_AREA)
        small = cv2.GaussianBlur(small, (0, 0), scaled_sigma, borderType=cv2.BORDER_REFLECT)
    else:
        inside = mask.astype(np.float32)
        total = cv2.resize(values * inside, reduced, interpolation=cv2.INTER_AREA)
        weight = cv2.resize(inside, reduced, interpolation=cv2.INTER_AREA)
        total = cv2.GaussianBlur(total, (0, 0), scaled_sigma, borderType=cv2.BORDER_CONSTANT)
        weight = cv2.GaussianBlur(weight, (0, 0), scaled_sigma, borderType=cv2.BORDER_CONSTANT)
        small = total / np.maximum(weight, 1e-6)
    return cv2.resize(small, (cols, rows), interpolation=cv2.INTER_LINEAR)


def _edge_ramp(length: int) -> NDArray[np.float32]:
    """1-D version of the taper for a full line: ``clip(2 (G * box) - 1, 0, 1)`` at pixel centres."""
    centres = np.arange(length) + 0.5
    scale = _TAPER_SIGMA * math.sqrt(2.0)
    blurred = 0.5 * (scipy.special.erf(centres / scale) - scipy.special.erf((centres - length) / scale))
    return np.clip(2.0 * blurred - 1.0, 0.0, 1.0).astype(np.float32)


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


def _window(name: str, rho: NDArray[np.float64]) -> NDArray[np.float64]:
    """Spectral window over the crop's normalised distance: 1 at ``rho = 0``, 0 for ``rho >= 1``."""
    inside = rho < 1.0
    if name == "rect":
        return inside.astype(np.float64)
    if name == "hann":
        return np.where(inside, np.cos(0.5 * np.pi * np.minimum(rho, 1.0)) ** 2, 0.0)
    # Tukey with a flat top over half the radius and a cosine edge over the other half
    edge = np.clip(2.0 * rho - 1.0, 0.0, 1.0)
    return np.where(inside, np.cos(0.5 * np.pi * edge) ** 2, 0.0)


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


def _sideband_field(
    spectrum: NDArray[np.complex64], shape: tuple[int, int], carrier_rc: tuple[float, float], window: str
) -> NDArray[np.complex64]:
    """Complex field ``2 (B/2) e^{i phi}`` (so ``|.| = B``) at full size, carrier removed.

    Only the sideband crop (:func:`_crop_rho`) is transformed: it is moved to DC
    (integer part of the carrier), inverse-transformed along y for its ``2 h + 1`` non-zero
    spectral columns only, then along x zero-padded to the full width (exact band-limited
    interpolation to full size, about half the work of a full 2-D inverse FFT). The sub-bin
    remainder of the carrier is removed by a conjugate ramp after each pass.
    """
    rows, cols = shape
    exact = (carrier_rc[0] * rows, carrier_rc[1] * cols)  # carrier in bins
    centre = (round(exact[0]), round(exact[1]))
    residual = (exact[0] - centre[0], exact[1] - centre[1])
    half = _crop_half(carrier_rc, shape)
    block = _spectrum_block(spectrum, shape, centre, half)
    dv = np.arange(-half[0], half[0] + 1)
    du = np.arange(-half[1], half[1] + 1)
    offsets = ((dv[:, None] - residual[0]) / rows, (du[None, :] - residual[1]) / cols)  # cycles/px
    rho = _crop_rho(offsets, carrier_rc)
    weights = (_window(window, rho) * (2.0 / (rows * cols))).astype(np.float32)
    # pass 1, along y, for the non-zero spectral columns only; then the y part of the sub-bin ramp
    partial = np.zeros((rows, du.size), dtype=np.complex64)
    partial[np.mod(dv, rows), :] = block * weights
    partial = scipy.fft.ifft(partial, axis=0, norm="forward", overwrite_x=True)
    partial *= np.exp(-2j * np.pi * residual[0] * np.arange(rows) / rows).astype(np.complex64)[:, None]
    # pass 2, along x (the contiguous axis), zero-padded to the full width; then the x ramp
    field = np.zeros(shape, dtype=np.complex64)
    field[:, np.mod(du, cols)] = partial
    field = scipy.fft.ifft(field, axis=1, norm="forward", overwrite_x=True)
    field *= np.exp(-2j * np.pi * residual[1] * np.arange(cols) / cols).astype(np.complex64)
    return field


# ----------------------------------------------------------------------------- public function


def carrier_phase(
    frame: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    carrier: ArrayLike | None = None,
    window: str = "hann",
    sign: int = +1,
    min_carrier_cycles: float = 4.0,
) -> CarrierResult:
    """Wrapped phase of one frame with carrier (tilt) fringes, carrier removed (Takeda's method).

    Parameters
    ----------
    frame : array_like, shape (rows, cols)
        Intensity image with straight-ish carrier fringes, any real dtype; rows, cols >= 16.
    mask : array_like of bool, shape (rows, cols), optional
        Valid pupil. The background is estimated inside it, and the frame minus the background
        is tapered smoothly to 0 at the mask edge (over ~5 px) before the FFT; default the whole
        frame, tapered at its border.
    carrier : (fx, fy), optional
        Known carrier in cycles per pixel (x = col, y = -row), used as given (no search, no
        refinement); it also selects which of the two sidebands is demodulated. Default: found
        from the data (module docstring).
    window : {"hann", "tukey", "rect"}
        Window over the sideband crop (up to ``|f|`` from the carrier, half-way towards DC; see
        the module docstring), in its normalised distance: Hann (cos^2), Tukey (flat over half
        the distance, cos^2 edge) or rectangular.
    sign : {+1, -1}
        -1 negates the phase and the reported carrier (the other sideband convention); a single
        carrier frame cannot tell ``phi`` from ``-phi`` without knowing the tilt direction.
    min_carrier_cycles : float
        Smallest carrier searched for, in fringes across the shorter side of the frame (> 0);
        keeps the search away from the background around DC.

    Returns
    -------
    CarrierResult
        Phase (radians), modulation ``B`` (intensity units), the carrier ``(fx, fy)`` in cycles
        per pixel and the window name.

    Raises
    ------
    ValueError
        If ``frame`` is not a finite real 2-D image of at least 16x16 pixels; ``mask`` is not a
        boolean array of the frame's shape with at least 256 true pixels; ``carrier`` is not two
        finite numbers below Nyquist giving at least 4 fringes across the frame; ``window``,
        ``sign`` or ``min_carrier_cycles`` is invalid; or (automatic search) no sideband stands
        clearly above the spectrum around it: "frame: no carrier fringes found; expected tilt
        fringes ...".

    References
    ----------
    M. Takeda, H. Ina and S. Kobayashi, "Fourier-transform method of fringe-pattern analysis for
    computer-based topography and interferometry", J. Opt. Soc. Am. 72(1), 156-160 (1982): the
    fringe model ``g = a + c e^{2 pi i f x} + c* e^{-2 pi i f x}`` with ``c = (b/2) e^{i phi}``,
    isolating one sideband ``C``, shifting it by the carrier to the origin and taking
    ``phi = arg(c)`` of its inverse transform. The sub-bin carrier estimate by the sideband
    power centroid is the first moment of the spectrum (Parseval): the carrier plus the
    modulation-weighted mean phase gradient.
    """
    image = _check_frame(frame)
    shape = (int(image.shape[0]), int(image.shape[1]))
    checked_mask = _check_mask(mask, shape)
    if window not in _WINDOWS:
        raise ValueError(f"window: expected one of {', '.join(_WINDOWS)}, got {window!r}")
    if isinstance(sign, bool) or sign not in (1, -1):
        raise ValueError(f"sign: expected +1 or -1, got {sign!r}")
    if not (isinstance(min_carrier_cycles, Real) and not isinstance(min_carrier_cycles, bool)
            and math.isfinite(min_carrier_cycles) and min_carrier_cycles > 0):
        raise ValueError(
            f"min_carrier_cycles: expected a positive number of fringes, got {min_carrier_cycles!r}"
        )
    given = None if carrier is None else _check_carrier(carrier, shape)

    values = image.astype(np.float32)
    values -= _background(values, checked_mask, 0.5 * min(shape) / min_carrier_cycles)
    values *= _taper(checked_mask, shape)
    scale = float(np.max(np.abs(image)))
    rms = float(np.sqrt(np.mean(np.square(values, dtype=np.float64))))
    if given is None and not rms > _MIN_RELATIVE_RMS * scale:
        raise ValueError("frame: no carrier fringes found; expected tilt fringes, but the frame is flat")
    spectrum = scipy.fft.rfft2(values)

    if given is None:
        carrier_rc = _find_carrier(spectrum, shape, min_carrier_cycles / min(shape))
    else:
        carrier_rc = (-given[1], given[0])
    field = _sideband_field(spectrum, shape, carrier_rc, window)

    phase = np.arctan2(field.imag, field.real)  # float32, as the complex64 field: ~1e-7 rad
    if sign < 0:
        np.negative(phase, out=phase)
    pi = np.float32(np.pi)  # float32's nearest pi; (-pi, pi] in that precision
    np.clip(phase, -pi, pi, out=phase)
    np.copyto(phase, pi, where=phase == -pi)
    modulation = np.abs(field)
    phase.flags.writeable = False
    modulation.flags.writeable = False
    fx, fy = carrier_rc[1], -carrier_rc[0]
    return CarrierResult(
        phase=phase, modulation=modulation, carrier=(sign * fx + 0.0, sign * fy + 0.0), window=window
    )
