"""From raw interferograms to a wavefront map on a detected aperture.

One place strings the signal path together, for a phase-shifted set or a single carrier frame:

1. phase: temporal phase shifting (:mod:`wavestack.pipeline.phase.psi`) or the Fourier carrier method
   (:mod:`wavestack.pipeline.phase.carrier`), with the modulation map alongside;
2. aperture: detected from the modulation (:mod:`wavestack.pipeline.aperture.detect`), so the
   mirror is found inside its speckled halo, its edge half way between the disk's and the halo's
   modulation; for a carrier frame from the local fringe energy (see
   :func:`_fringe_energy`). Or, by ``aperture=``, the circle fitted to that edge (for a
   round optic) or the user's mask (:func:`~wavestack.pipeline.aperture.choice.choose_aperture`);
3. unwrapping on that aperture (:mod:`wavestack.pipeline.phase.spatial_unwrap`);
4. units: waves (``phase / 2 pi``), and nanometres with the wavelength.

Sign convention (all inputs alike): frames are ``I_k = A + B cos(phi + delta_k)``; a positive
phi is a positive wavefront. Counter-clockwise steps (``direction="ccw"``) mean
``delta_k = +k step``. Measured maps from files are taken with the sign the file gives.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..aperture import Aperture, DetectionSettings, EdgeCircle, choose_aperture
from .carrier import carrier_phase
from .psi.algorithms import phase_from_frames
from .spatial_unwrap import SpatialParams, unwrap_spatial


# OpenCV's histogram unwrapper slows down badly on noisy maps (measured at 1024^2: 57 s with
# 0.3 rad RMS noise); unwrapping a lightly smoothed copy and snapping each raw pixel to the
# nearest 2 pi k keeps it under a second and leaves correctly unwrapped pixels unchanged.
_UNWRAP = SpatialParams(prefilter_sigma_px=1.5)
# Modulation below this fraction of the frames' largest value is none: identical frames give
# about 1e-15 (rounding), while one count of an 8-bit camera is 4e-3 of full scale.
_NO_MODULATION = 1e-6


@dataclass(frozen=True, eq=False)
class MeasuredWavefront:
    """A wavefront map and how it was obtained.

    Attributes
    ----------
    waves : ndarray, shape (rows, cols)
        Wavefront in waves, NaN outside the aperture.
    aperture : Aperture
        The aperture used (detected, fitted circle or given mask).
    method : str
        "lsq", "four", "hariharan", "aia", "pca", "carrier" or "file".
    steps_rad : ndarray or None
        Phase steps used (estimated for aia/pca), radians.
    modulation : ndarray or None
        Fringe modulation, intensity units.
    carrier : (fx, fy) or None
        Carrier frequency in cycles per pixel (x right, y up) for the carrier method.
    timings : dict
        Seconds per stage.
    aperture_choice : str
        ``"detected"``, ``"circle"``, ``"mask"`` (the user's) or ``"file"`` (a measured map).
    edge : EdgeCircle or None
        Circle fitted to the detected edge: centre, radius and their uncertainties in pixels
        (None for a user mask, a measured map, or an edge no circle fits).
    """

    waves: NDArray[np.float64]
    aperture: Aperture
    method: str
    steps_rad: NDArray[np.float64] | None = None
    modulation: NDArray[np.float64] | None = None
    carrier: tuple[float, float] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    aperture_choice: str = "detected"
    edge: EdgeCircle | None = None


def local_fringe_contrast(frame: NDArray, period_px: float) -> NDArray[np.float32]:
    """Local standard deviation of a frame over a box of about two fringe periods.

    High wherever there are fringes, whatever their local frequency. The carrier method's
    sideband modulation is not: where the mirror's own aberration moves the local fringe
    frequency outside the sideband window it falls to zero, so it is a poor aperture detector.

    Parameters
    ----------
    frame : ndarray, shape (rows, cols)
    period_px : float
        Carrier fringe period in pixels.

    Returns
    -------
    ndarray of float32, shape (rows, cols)
    """
    size = _contrast_box(period_px)
    # float32 throughout (counts up to 65535 square to < 2^32, well inside float32's range; the
    # variance's cancellation error is ~1e-7 of the mean square, far below any fringe contrast),
    # and OpenCV's box filter of squares: two passes instead of four float64 ones.
    values = np.asarray(frame, dtype=np.float32)
    mean = cv2.boxFilter(values, cv2.CV_32F, (size, size))
    square = cv2.sqrBoxFilter(values, cv2.CV_32F, (size, size))
    cv2.multiply(mean, mean, dst=mean)
    cv2.subtract(square, mean, dst=square)
    np.maximum(square, 0.0, out=square)
    return np.sqrt(square, out=square)


def _fringe_energy(frame: NDArray, period_px: float) -> NDArray[np.float32]:
    """Local fringe energy: the squared deviation from the background, smoothed over a quarter period.

    ``E = G_(P/4) * (I - B)**2`` with ``B`` the frame's mean over a box of about two periods
    ``P`` (:func:`local_fringe_contrast`'s box). For fringes ``B + b cos(phi)``, ``(I - B)**2``
    is ``b**2 / 2 (1 + cos(2 phi))``; a Gaussian of ``sigma = P / 4`` passes
    ``exp(-pi**2 / 2)``, 0.7 %, of the ``cos(2 phi)`` ripple, so ``E`` is ``b**2 / 2`` inside
    the disk and the halo's speckle energy outside, with an edge response only ~2 sigma wide
    either side of the edge and symmetric about it: the half-way level is the edge.

    Why not the box variance (the square of :func:`local_fringe_contrast`), as before: its edge
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
    size = _contrast_box(period_px)
    background = cv2.boxFilter(values, cv2.CV_32F, (size, size), borderType=cv2.BORDER_REFLECT)
    cv2.subtract(values, background, dst=background)
    cv2.multiply(background, background, dst=background)
    return cv2.GaussianBlur(background, (0, 0), period_px / 4.0, borderType=cv2.BORDER_REFLECT)


def _contrast_box(period_px: float) -> int:
    """Side of the local-contrast box, pixels: about two periods, odd, at least 3."""
    return max(3, int(round(2 * period_px)) | 1)


def _finish(
    phase: NDArray[np.float64],
    signal: NDArray,
    choice: str | ArrayLike,
    detection: DetectionSettings,
    timings: dict[str, float],
) -> dict:
    """Aperture (by ``choice``) and unwrapped waves: the MeasuredWavefront fields they fill."""
    tick = time.perf_counter()
    chosen = choose_aperture(signal, choice, detection)
    timings["aperture"] = time.perf_counter() - tick
    tick = time.perf_counter()
    unwrapped = unwrap_spatial(phase, chosen.aperture.mask, _UNWRAP)
    timings["unwrap"] = time.perf_counter() - tick
    return {
        "waves": unwrapped / (2.0 * np.pi), "aperture": chosen.aperture,
        "aperture_choice": chosen.choice, "edge": chosen.edge, "timings": timings,
    }


def wavefront_from_phase_shifts(
    frames: NDArray,
    *,
    method: str = "lsq",
    steps_rad: NDArray[np.float64] | None = None,
    direction: str = "ccw",
    detection: DetectionSettings = DetectionSettings(),
    aperture: str | ArrayLike = "detected",
) -> MeasuredWavefront:
    """Wavefront of a phase-shifted set of frames.

    Parameters
    ----------
    frames : ndarray, shape (N, rows, cols)
        Interferograms in stepping order.
    method : {"lsq", "four", "hariharan", "aia", "pca"}
        Phase algorithm; ``aia`` and ``pca`` estimate the steps from the data.
    steps_rad : ndarray, shape (N,), optional
        Known steps for ``lsq`` (default: N equal steps over one cycle, ``2 pi k / N``); the
        starting guess for ``aia``.
    direction : {"ccw", "cw"}
        Phase-step direction.
    detection : DetectionSettings
        How the aperture is found in the modulation map.
    aperture : {"detected", "circle"} or array_like of bool, shape (rows, cols)
        The detected aperture (any shape, default), the circle fitted to its edge, or a mask.

    Returns
    -------
    MeasuredWavefront

    Raises
    ------
    ValueError
        If the frames show no fringe modulation (e.g. identical frames), anywhere or in the
        median over the aperture.
    """
    frames = np.asarray(frames)
    timings: dict[str, float] = {}
    tick = time.perf_counter()
    if steps_rad is None and method in ("lsq", "aia"):
        steps_rad = 2.0 * np.pi * np.arange(frames.shape[0]) / frames.shape[0]
    result = phase_from_frames(frames, method=method, steps=steps_rad, direction=direction)
    timings["phase"] = time.perf_counter() - tick
    level = float(np.max(np.abs(frames))) if frames.size else 0.0
    check_fringe_modulation(result.modulation, None, level)
    finished = _finish(result.phase, result.modulation, aperture, detection, timings)
    check_fringe_modulation(result.modulation, finished["aperture"].mask, level)
    return MeasuredWavefront(
        method=result.method,
        steps_rad=np.asarray(result.steps),
        modulation=result.modulation,
        **finished,
    )


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
        If the modulation is at most ``_NO_MODULATION`` times ``level`` (the frames' largest
        value): identical frames hold no phase, and their "flat" map would be a fiction.
    """
    values = np.asarray(modulation, dtype=np.float64)
    where = "" if mask is None else " in the aperture (median)"
    found = float(np.nanmax(values)) if mask is None else float(np.nanmedian(values[mask]))
    if not found > _NO_MODULATION * level:
        raise ValueError(f"the frames show no fringe modulation{where} ({found:.3g} against frame values up to "
                         f"{level:.3g}); expected phase-shifted fringes, not identical frames")


def wavefront_from_carrier(
    frame: NDArray,
    *,
    sign: int = 1,
    detection: DetectionSettings = DetectionSettings(),
    aperture: str | ArrayLike = "detected",
) -> MeasuredWavefront:
    """Wavefront of a single frame with carrier (tilt) fringes, by the Fourier method.

    Parameters
    ----------
    frame : ndarray, shape (rows, cols)
    sign : {1, -1}
        A single carrier frame cannot tell phi from -phi without knowing the tilt's direction;
        -1 flips the result to match a setup whose tilt runs the other way.
    detection : DetectionSettings
    aperture : {"detected", "circle"} or array_like of bool, shape (rows, cols)
        As for :func:`wavefront_from_phase_shifts`, detected in the local fringe energy
        (see ``_fringe_energy``), whose half-way level is at the mirror's edge.

    Returns
    -------
    MeasuredWavefront

    Raises
    ------
    ValueError
        If the frame shows no carrier fringes.
    """
    timings: dict[str, float] = {}
    tick = time.perf_counter()
    result = carrier_phase(np.asarray(frame), sign=sign)
    timings["phase"] = time.perf_counter() - tick
    period = 1.0 / float(np.hypot(*result.carrier))
    energy = _fringe_energy(frame, period)
    # the background box's step residue reaches half a box out: the levels are taken beyond it
    margin = max(detection.edge_margin_px, _contrast_box(period) // 2 + 3)
    detection = dataclasses.replace(detection, edge_margin_px=margin)
    return MeasuredWavefront(
        method="carrier",
        modulation=result.modulation,
        carrier=tuple(result.carrier),
        **_finish(result.phase, energy, aperture, detection, timings),
    )
