"""Spatial phase unwrapping (OpenCV histogram method), and the pieces temporal unwrapping shares.

Spatial unwrapping of one wrapped phase map uses OpenCV contrib's quality-guided
``cv2.phase_unwrapping.HistogramPhaseUnwrapping`` [1]_ [2]_ with the aperture mask as shadow
mask (:func:`unwrap_spatial`). Temporal unwrapping, for live streams, adds to the previous
unwrapped phase the pixelwise wrapped difference to it and falls back to the spatial method
when that difference is not trustworthy
(:class:`~wavestack.pipeline.phase.temporal_unwrap.TemporalUnwrapper`).

Conventions
-----------
* Phases are in radians. Wrapped input may lie in any range (it is used modulo 2 pi); the
  unwrapped output is float64, congruent modulo 2 pi to the float64 input at every valid
  pixel (to float64 rounding), and NaN outside the mask.
* Unwrapping is defined only up to ``2 pi k`` per connected component of the mask (pixels
  connect through their four horizontal and vertical neighbours, the edges the histogram
  method unwraps along). :func:`unwrap_spatial` picks ``k`` per component so that the median
  of the unwrapped phase over the component lies in ``[-pi, pi)``.
  :class:`~wavestack.pipeline.phase.temporal_unwrap.TemporalUnwrapper` keeps the level
  continuous instead (see there).

OpenCV notes
------------
Measured with opencv-contrib-python-headless 5.0.0, numpy 2.4, on a 2-core machine; the
reasons come from reading ``modules/phase_unwrapping/src/histogramphaseunwrapping.cpp`` in
opencv_contrib.

* A fresh unwrapper object is built for every call. Reusing one is slower and wrong: on a
  1024 x 1024 annulus with two different smooth maps A and B (tens of radians of tilt and
  defocus), a fresh object gives about 6e-7 rad RMS error (float32 rounding) on every call,
  in 0.38-0.40 s; one object reused for A, B, A, B gives 6e-7, 18.2, 0.45 and 18.2 rad RMS
  error (after removing the best constant 2 pi k) in 0.38, 0.36, 0.69 and 1.16 s. The
  implementation appends the pixels and the histogram bins of every call to member vectors
  that are never cleared, so a second call works on the first call's pixels. The project
  issue measured 0.27 rad instead of 0.018 rad on its data; same mechanism. Nothing in that
  code is specific to OpenCV 5, so 4.x is very likely affected too.
* Run time depends strongly on noise. Merging two pixel groups scans every pixel of the map,
  so a map whose reliability order creates many groups (noise) costs up to O(N^2): at
  1024 x 1024 a smooth map takes about 0.4-0.5 s, the same map with 0.3 rad RMS noise 57 s
  and with 0.4 rad 91 s (512 x 512: 0.06 s smooth, 0.43 s at 0.2 rad, 1.7 s at 0.3 rad).
  ``SpatialParams.prefilter_sigma_px`` avoids this: OpenCV then unwraps a smoothed copy of
  the map and every raw pixel takes the multiple of 2 pi that brings it closest to that
  guide (0.4-0.6 s at 1024 x 1024 for noise up to 0.8 rad RMS).
* The Python names differ between releases: ``cv2.phase_unwrapping.HistogramPhaseUnwrapping
  .Params`` with ``HistogramPhaseUnwrapping.create`` (OpenCV 5), or
  ``cv2.phase_unwrapping.HistogramPhaseUnwrapping_Params`` /
  ``cv2.phase_unwrapping_HistogramPhaseUnwrapping_Params`` with
  ``cv2.phase_unwrapping.HistogramPhaseUnwrapping_create`` (OpenCV 4). The layout is looked
  up on every call. The attributes set are ``width`` (columns), ``height`` (rows),
  ``histThresh``, ``nbrOfSmallBins`` and ``nbrOfLargeBins``; OpenCV indexes its pixels with
  ``width`` and ``height``, so they must match the map (the defaults are 800 x 600).
* OpenCV needs a CV_32FC1 wrapped map in ``[-pi, pi]`` and a CV_8UC1 shadow mask (255 =
  valid). Its float32 result ``u32`` is snapped back onto the float64 input ``w``:
  ``u = w + 2 pi rint((u32 - w) / 2 pi)``, which removes the float32 rounding.

References
----------
.. [1] M. A. Herraez, D. R. Burton, M. J. Lalor and M. A. Gdeisat, "Fast two-dimensional
   phase-unwrapping algorithm based on sorting by reliability following a noncontinuous
   path", Applied Optics 41(35), 7437-7444 (2002).
.. [2] "A novel algorithm based on histogram processing of reliability for two-dimensional
   phase unwrapping", Optik (2015), the paper OpenCV cites as ``histogramUnwrapping``.
.. [3] R. M. Goldstein, H. A. Zebker and C. L. Werner, "Satellite radar interferometry:
   two-dimensional phase unwrapping", Radio Science 23(4), 713-720 (1988) (residues).
.. [4] J. M. Huntley and H. Saldner, "Temporal phase-unwrapping algorithm for automated
   interferogram analysis", Applied Optics 32(17), 3047-3052 (1993).
.. [5] OpenCV contrib documentation, module ``phase_unwrapping``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import int_at_least, is_real, real_array
from ..aperture import EmptyAperture
from .residues import _TWO_PI, _components, _count_residues, _shift_components, _wrap

__all__ = [
    "SpatialParams",
    "count_residues",
    "unwrap_spatial",
    "wrap_phase",
]

logger = logging.getLogger(__name__)

_MAX_EDGE_RELIABILITY = 32.0 * math.pi**2  # upper end of OpenCV's edge reliability range


# ----------------------------------------------------------------------------- public types


@dataclass(frozen=True)
class SpatialParams:
    """Settings of the spatial method.

    The first three are OpenCV's histogram settings (defaults are OpenCV's): edge
    reliabilities (sums of two pixel inverse reliabilities, in rad^2, from 0 to 32 pi^2) are
    sorted into ``n_small_bins`` bins below ``hist_thresh`` and ``n_large_bins`` above it.

    Attributes
    ----------
    hist_thresh : float
        Split between small and large bins, in rad^2 (OpenCV ``histThresh``, default
        ``3 pi^2``). Must lie in ``(0, 32 pi^2)``.
    n_small_bins : int
        Bins below ``hist_thresh`` (OpenCV ``nbrOfSmallBins``, default 10), >= 1.
    n_large_bins : int
        Bins above ``hist_thresh`` (OpenCV ``nbrOfLargeBins``, default 5), >= 1.
    prefilter_sigma_px : float
        0 (default) unwraps the map itself. A positive value, in pixels, unwraps a guide
        instead: the angle of ``mask * exp(i wrapped)`` smoothed by a Gaussian of this
        standard deviation; each raw pixel then takes the multiple of 2 pi that brings it
        within pi of the guide. Use 1-2 px for noisy maps (see the module notes on run
        time). The guide is biased near the mask edge by about ``0.8 sigma`` times the
        local phase gradient, so keep ``sigma * gradient`` well below pi rad. Finite, >= 0.
    """

    hist_thresh: float = 3.0 * math.pi**2
    n_small_bins: int = 10
    n_large_bins: int = 5
    prefilter_sigma_px: float = 0.0

    def __post_init__(self) -> None:
        if not is_real(self.hist_thresh) or not 0.0 < self.hist_thresh < _MAX_EDGE_RELIABILITY:
            raise ValueError(
                f"hist_thresh must be a real number in (0, 32 pi^2 = {_MAX_EDGE_RELIABILITY:.4g})"
                f" rad^2, got {self.hist_thresh!r}"
            )
        for name in ("n_small_bins", "n_large_bins"):
            int_at_least(getattr(self, name), name, 1)
        sigma = self.prefilter_sigma_px
        if not is_real(sigma) or not math.isfinite(sigma) or sigma < 0.0:
            raise ValueError(f"prefilter_sigma_px must be a finite number >= 0 px, got {sigma!r}")


# ----------------------------------------------------------------------------- public functions


def wrap_phase(phase: ArrayLike) -> NDArray[np.float64]:
    """Wrap a phase into ``[-pi, pi]``.

    Parameters
    ----------
    phase : array_like
        Phase in radians, any shape; NaN stays NaN.

    Returns
    -------
    NDArray[np.float64]
        ``phase - 2 pi rint(phase / 2 pi)``, same shape, in ``[-pi, pi]`` (both ends can
        occur: ``rint`` rounds half to even).

    Raises
    ------
    ValueError
        If ``phase`` is not real numeric (booleans and complex numbers are refused).

    References
    ----------
    .. [1] D. C. Ghiglia and M. D. Pritt, *Two-Dimensional Phase Unwrapping* (Wiley, 1998),
       ch. 1 (the wrapping operator).
    """
    return _wrap(real_array(phase, "phase"))


def count_residues(wrapped: ArrayLike, mask: ArrayLike) -> int:
    """Count the phase residues of a wrapped map inside a mask.

    A residue is a 2 x 2 pixel loop, all four pixels valid, around which the sum of the
    wrapped phase differences is not zero (it is then +-2 pi) [1]_: a point where no
    consistent unwrapping exists, from noise, undersampling or a phase discontinuity.

    Parameters
    ----------
    wrapped : array_like, shape (rows, cols)
        Wrapped phase in radians (any range, used modulo 2 pi), finite inside the mask.
    mask : array_like, shape (rows, cols)
        Boolean or real numeric array; non-zero entries are valid pixels.

    Returns
    -------
    int
        Number of residues, positive and negative together, among the
        ``(rows - 1) x (cols - 1)`` loops whose four pixels are valid.

    Raises
    ------
    ValueError
        If the arrays are not 2-D of the same shape with at least 2 rows and 2 columns,
        ``wrapped`` is not real or not finite at a valid pixel, or ``mask`` is not boolean
        or finite real numeric.
    EmptyAperture
        If ``mask`` has no valid pixel (a ``ValueError``).

    References
    ----------
    .. [1] R. M. Goldstein, H. A. Zebker and C. L. Werner, Radio Science 23(4), 713-720 (1988).
    """
    values, valid = _validated_frame(wrapped, mask)
    return _count_residues(values, valid)


def unwrap_spatial(
    wrapped: ArrayLike, mask: ArrayLike, params: SpatialParams | None = None
) -> NDArray[np.float64]:
    """Unwrap one phase map with OpenCV's histogram (reliability-sorting) method.

    A new ``HistogramPhaseUnwrapping`` object is built for every call: reusing one gives
    wrong results (see the module notes).

    Parameters
    ----------
    wrapped : array_like, shape (rows, cols)
        Wrapped phase in radians (any range, used modulo 2 pi). Must be finite inside the
        mask; values outside the mask are ignored (they may be NaN).
    mask : array_like, shape (rows, cols)
        Boolean or real numeric array; non-zero entries are valid pixels. Passed to OpenCV
        as the uint8 shadow mask (255 = valid).
    params : SpatialParams, optional
        Histogram settings and optional prefilter; OpenCV's defaults, no prefilter, when
        omitted.

    Returns
    -------
    NDArray[np.float64], shape (rows, cols)
        Unwrapped phase in radians, NaN outside the mask, congruent to ``wrapped`` modulo
        2 pi at every valid pixel. Each 4-connected component of the mask is shifted by a
        multiple of 2 pi so that its median lies in ``[-pi, pi)``.

    Raises
    ------
    ValueError
        If the arrays are not 2-D of the same shape with at least 2 rows and 2 columns,
        ``wrapped`` is not real or not finite at a valid pixel, ``mask`` is not boolean or
        finite real numeric, or ``params`` is not a :class:`SpatialParams`.
    EmptyAperture
        If ``mask`` has no valid pixel (a ``ValueError``).
    RuntimeError
        If this OpenCV build has no ``phase_unwrapping`` module (opencv-contrib missing).

    References
    ----------
    .. [1] M. A. Herraez et al., Applied Optics 41(35), 7437-7444 (2002).
    .. [2] OpenCV contrib, ``cv::phase_unwrapping::HistogramPhaseUnwrapping``.
    """
    values, valid = _validated_frame(wrapped, mask)
    settings = _validated_params(params)
    phase = _unwrap_with_opencv(values, valid, settings)
    labels, count = _components(valid)
    return _shift_components(phase, labels, count, reference=None, reference_valid=None)


# ----------------------------------------------------------------------------- OpenCV


def _histogram_api(cv: Any) -> tuple[Callable[[], Any], Callable[[Any], Any]]:
    """Find the ``HistogramPhaseUnwrapping`` Params type and factory (OpenCV 4 or 5 names).

    Tried in order: ``phase_unwrapping.HistogramPhaseUnwrapping.Params`` / ``.create``
    (OpenCV 5), ``phase_unwrapping.HistogramPhaseUnwrapping_Params`` and top-level
    ``phase_unwrapping_HistogramPhaseUnwrapping_Params`` / ``phase_unwrapping
    .HistogramPhaseUnwrapping_create`` (OpenCV 4).
    """
    module = getattr(cv, "phase_unwrapping", None)
    nested = getattr(module, "HistogramPhaseUnwrapping", None)
    params_candidates = (
        getattr(nested, "Params", None),
        getattr(module, "HistogramPhaseUnwrapping_Params", None),
        getattr(cv, "phase_unwrapping_HistogramPhaseUnwrapping_Params", None),
    )
    create_candidates = (
        getattr(nested, "create", None),
        getattr(module, "HistogramPhaseUnwrapping_create", None),
        getattr(getattr(cv, "phase_unwrapping_HistogramPhaseUnwrapping", None), "create", None),
    )
    make_params = next((c for c in params_candidates if callable(c)), None)
    create = next((c for c in create_candidates if callable(c)), None)
    if make_params is None or create is None:
        raise RuntimeError(
            "OpenCV has no usable phase_unwrapping.HistogramPhaseUnwrapping (Params type or"
            " create function not found); install opencv-contrib-python-headless"
        )
    return make_params, create


def _create_unwrapper(rows: int, cols: int, params: SpatialParams, cv: Any = cv2) -> Any:
    """Build a fresh OpenCV histogram unwrapper for a ``rows x cols`` map."""
    make_params, create = _histogram_api(cv)
    settings = make_params()
    settings.width = int(cols)
    settings.height = int(rows)
    settings.histThresh = float(params.hist_thresh)
    settings.nbrOfSmallBins = int(params.n_small_bins)
    settings.nbrOfLargeBins = int(params.n_large_bins)
    return create(settings)


def _unwrap_with_opencv(
    values: NDArray[np.float64], valid: NDArray[np.bool_], params: SpatialParams
) -> NDArray[np.float64]:
    """Unwrap with a fresh OpenCV object; float64 result snapped onto the input, NaN outside."""
    rows, cols = valid.shape
    wrapped = _wrap(np.where(valid, values, 0.0))
    guide = wrapped if params.prefilter_sigma_px == 0.0 else _smoothed(wrapped, valid, params)
    shadow = np.where(valid, np.uint8(255), np.uint8(0))
    unwrapper = _create_unwrapper(rows, cols, params)
    raw = unwrapper.unwrapPhaseMap(np.ascontiguousarray(guide, dtype=np.float32), shadowMask=shadow)
    turns = np.rint((np.asarray(raw, dtype=np.float64).reshape(rows, cols) - wrapped) / _TWO_PI)
    phase = wrapped + _TWO_PI * turns
    phase[~valid] = np.nan
    return phase


def _smoothed(
    wrapped: NDArray[np.float64], valid: NDArray[np.bool_], params: SpatialParams
) -> NDArray[np.float64]:
    """Angle of the Gaussian-smoothed unit phasors of the valid pixels (0 where none)."""
    sigma = float(params.prefilter_sigma_px)
    parts = []
    for part in (np.cos(wrapped), np.sin(wrapped)):
        masked = np.where(valid, part, 0.0).astype(np.float32)
        blurred = cv2.GaussianBlur(masked, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
        parts.append(np.asarray(blurred, dtype=np.float64))
    return np.arctan2(parts[1], parts[0])


# ----------------------------------------------------------------------------- helpers


def _validated_frame(
    wrapped: ArrayLike, mask: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Check a wrapped map and its mask; return float64 values and a boolean mask."""
    values = real_array(wrapped, "wrapped")
    if values.ndim != 2 or values.shape[0] < 2 or values.shape[1] < 2:
        raise ValueError(
            "wrapped must be a 2-D array with at least 2 rows and 2 columns, got shape"
            f" {values.shape}"
        )
    raw_mask = np.asarray(mask)
    if raw_mask.shape != values.shape:
        raise ValueError(
            f"mask must have the shape of wrapped {values.shape}, got {raw_mask.shape}"
        )
    if raw_mask.dtype == np.bool_:
        valid = raw_mask
    elif np.issubdtype(raw_mask.dtype, np.integer):
        valid = raw_mask != 0
    elif np.issubdtype(raw_mask.dtype, np.floating):
        if not np.isfinite(raw_mask).all():
            raise ValueError("mask must be finite (boolean or real numeric, non-zero = valid)")
        valid = raw_mask != 0
    else:
        raise ValueError(
            f"mask must be boolean or real numeric (non-zero = valid), got dtype {raw_mask.dtype}"
        )
    valid = np.ascontiguousarray(valid)
    if not valid.any():
        raise EmptyAperture(f"mask of shape {valid.shape} has no valid (non-zero) pixel")
    finite = np.isfinite(values)
    if not finite.all():
        bad = int(np.count_nonzero(valid & ~finite))
        if bad:
            raise ValueError(f"wrapped must be finite inside the mask; {bad} valid pixels are not")
    return values, valid


def _validated_params(params: SpatialParams | None) -> SpatialParams:
    if params is None:
        return SpatialParams()
    if not isinstance(params, SpatialParams):
        raise ValueError(f"params must be a SpatialParams or None, got {type(params).__name__}")
    return params
