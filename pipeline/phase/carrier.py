"""Single-frame phase from carrier (tilt) fringes: the Fourier-transform method.

Sign convention (project-wide, as in :mod:`wavestack.pipeline.phase.psi`)
-------------------------------------------------------------------------
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

import cv2
import numpy as np
import scipy.fft
import scipy.special
from numpy.typing import ArrayLike, NDArray

from .._checks import is_finite_real, one_of, optional_mask
from .carrier_spectrum import _crop_half, _crop_rho, _find_carrier, _spectrum_block

_WINDOWS = ("hann", "tukey", "rect")
_TAPER_SIGMA = 2.0  # px: Gaussian softening of the frame / mask edge before the FFT
_MIN_RELATIVE_RMS = 1e-5  # background-removed frame RMS / max |frame| below which there are no fringes
_MIN_SIDE = 16  # px: smallest frame side accepted


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
    return optional_mask(mask, shape, min_true=_MIN_SIDE * _MIN_SIDE, shape_of="that of the frame")


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
    one_of(window, "window", _WINDOWS, voice="expected")
    if isinstance(sign, bool) or sign not in (1, -1):
        raise ValueError(f"sign: expected +1 or -1, got {sign!r}")
    if not (is_finite_real(min_carrier_cycles) and min_carrier_cycles > 0):
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
