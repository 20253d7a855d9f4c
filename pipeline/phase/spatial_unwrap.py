"""Phase unwrapping: spatial (OpenCV histogram method) and temporal (frame to frame).

Spatial unwrapping of one wrapped phase map uses OpenCV contrib's quality-guided
``cv2.phase_unwrapping.HistogramPhaseUnwrapping`` [1]_ [2]_ with the aperture mask as shadow
mask (:func:`unwrap_spatial`). Temporal unwrapping, for live streams, adds to the previous
unwrapped phase the pixelwise wrapped difference to it and falls back to the spatial method
when that difference is not trustworthy (:class:`TemporalUnwrapper`).

Conventions
-----------
* Phases are in radians. Wrapped input may lie in any range (it is used modulo 2 pi); the
  unwrapped output is float64, congruent modulo 2 pi to the float64 input at every valid
  pixel (to float64 rounding), and NaN outside the mask.
* Unwrapping is defined only up to ``2 pi k`` per connected component of the mask (pixels
  connect through their four horizontal and vertical neighbours, the edges the histogram
  method unwraps along). :func:`unwrap_spatial` picks ``k`` per component so that the median
  of the unwrapped phase over the component lies in ``[-pi, pi)``. :class:`TemporalUnwrapper`
  keeps the level continuous instead (see there).

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
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from ..aperture import EmptyAperture
from ..aperture import aperture_iou

__all__ = [
    "SpatialParams",
    "TemporalUnwrapper",
    "UnwrapResult",
    "count_residues",
    "unwrap_spatial",
    "wrap_phase",
]

logger = logging.getLogger(__name__)

_TWO_PI = 2.0 * math.pi
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
        if not _is_real(self.hist_thresh) or not 0.0 < self.hist_thresh < _MAX_EDGE_RELIABILITY:
            raise ValueError(
                f"hist_thresh must be a real number in (0, 32 pi^2 = {_MAX_EDGE_RELIABILITY:.4g})"
                f" rad^2, got {self.hist_thresh!r}"
            )
        for name in ("n_small_bins", "n_large_bins"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        sigma = self.prefilter_sigma_px
        if not _is_real(sigma) or not math.isfinite(sigma) or sigma < 0.0:
            raise ValueError(f"prefilter_sigma_px must be a finite number >= 0 px, got {sigma!r}")


@dataclass(frozen=True, eq=False)
class UnwrapResult:
    """One frame unwrapped by :class:`TemporalUnwrapper`.

    Attributes
    ----------
    phase : NDArray[np.float64], shape (rows, cols)
        Unwrapped phase in radians, NaN outside the mask. Read-only: the unwrapper keeps it
        as the reference for the next frame (copy it to modify it).
    path : {"spatial", "temporal"}
        Which method produced ``phase``.
    residues : int
        Residues counted by the check that chose the path: in the frame-difference map when
        a temporal step was tried (kept or rejected), in the wrapped input when the spatial
        method ran without trying (no previous frame, shape or mask changed).
    reason : str
        Why this path ran, e.g. ``"mask changed (IoU 0.9871)"``.
    """

    phase: NDArray[np.float64]
    path: Literal["spatial", "temporal"]
    residues: int
    reason: str


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
    return _wrap(_real_array(phase, "phase"))


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


# ----------------------------------------------------------------------------- temporal


class TemporalUnwrapper:
    """Frame-to-frame phase unwrapper for live streams, with spatial fallback.

    Holds the previous unwrapped phase and its mask. Each new frame is unwrapped as::

        d = wrap(wrapped - previous)        # pixelwise, in [-pi, pi]
        phase = previous + d

    (``wrap(wrapped - wrap(previous))`` is the same ``d``). That is right when the true change
    since the previous frame is spatially smooth and within ``(-pi, pi)`` everywhere [1]_.
    The spatial method (:func:`unwrap_spatial`) runs instead when

    * there is no previous frame (first frame, or after :meth:`reset`);
    * the frame shape or the mask changed. Any change counts: an IoU threshold was
      considered and rejected, because the temporal step needs a previous value at every
      valid pixel and newly valid pixels would have to be extrapolated, at the aperture edge
      where the data are worst. The IoU is reported in the reason;
    * the difference map ``d`` has more than ``max_residues`` residues (2 x 2 loops of valid
      pixels with a non-zero sum of wrapped differences [2]_): a discontinuous or noisy
      change;
    * ``d`` jumps by more than pi between neighbouring valid pixels on more than
      ``max_wrap_edges`` horizontal and vertical pixel edges. That happens along the border
      of every region where the true change passed an odd multiple of pi, i.e. where the
      frame-to-frame change exceeded pi over an area. A smooth change of that kind leaves
      no residue (``d`` is then a wrapped smooth field), so this count is what catches it.

    With the defaults (both 0) any such defect triggers the fallback, on purpose: a pixel
    given the wrong multiple of 2 pi by a temporal step keeps that error in every later
    temporal step (the next difference is taken to it), whereas the spatial method starts
    afresh. The difference map carries the noise of both frames (sqrt(2) times the noise of
    one), so noisy streams (about 0.3 rad RMS per frame and above at 1024 x 1024) fall back
    more and more often; raise the limits only where isolated 2 pi errors are acceptable.

    Level convention: the first frame after construction or :meth:`reset`, or after a
    shape change, uses :func:`unwrap_spatial`'s convention. After any other fallback each
    4-connected component of the mask is shifted by the multiple of 2 pi that brings the
    median of (new - previous), over its pixels valid in both frames, into ``[-pi, pi)``,
    so the level stays continuous; components without such pixels use the standalone
    convention.

    Parameters
    ----------
    max_residues : int, optional
        Residues allowed in the difference map (>= 0, default 0).
    max_wrap_edges : int, optional
        Pixel edges allowed where the difference map jumps by more than pi (>= 0, default 0).
    params : SpatialParams, optional
        Settings of the spatial method. For noisy streams set ``prefilter_sigma_px``: without
        it a fallback on a noisy 1024 x 1024 frame can take tens of seconds.

    Raises
    ------
    ValueError
        If a limit is not an integer >= 0 or ``params`` is not a :class:`SpatialParams`.

    Notes
    -----
    A temporal step is a few vectorised passes over the frame with preallocated scratch
    buffers: about 5-9 ms at 1024 x 1024 (float64 input, 2-core machine, median over 200
    frames; up to ~15 ms when the machine is loaded), against 0.4-0.7 s for a spatial step
    on a smooth map. A temporal result is congruent to the input modulo 2 pi to float64
    rounding, so it does not drift: errors can only be whole multiples of 2 pi. Not
    thread-safe: use one instance per stream.

    References
    ----------
    .. [1] J. M. Huntley and H. Saldner, Applied Optics 32(17), 3047-3052 (1993).
    .. [2] R. M. Goldstein, H. A. Zebker and C. L. Werner, Radio Science 23(4), 713-720 (1988).
    """

    __slots__ = ("_mask", "_max_residues", "_max_wrap_edges", "_params", "_phase", "_work")

    def __init__(
        self,
        *,
        max_residues: int = 0,
        max_wrap_edges: int = 0,
        params: SpatialParams | None = None,
    ) -> None:
        self._max_residues = _validated_limit(max_residues, "max_residues")
        self._max_wrap_edges = _validated_limit(max_wrap_edges, "max_wrap_edges")
        self._params = _validated_params(params)
        self._phase: NDArray[np.float64] | None = None
        self._mask: NDArray[np.bool_] | None = None
        self._work: _Workspace | None = None  # loop mask and scratch buffers of this shape

    def reset(self) -> None:
        """Forget the previous frame; the next :meth:`update` unwraps spatially."""
        self._phase = None
        self._mask = None
        self._work = None

    def update(self, wrapped: ArrayLike, mask: ArrayLike) -> UnwrapResult:
        """Unwrap the next frame of the stream.

        Parameters
        ----------
        wrapped : array_like, shape (rows, cols)
            Wrapped phase in radians (any range, used modulo 2 pi). Must be finite inside
            the mask; values outside are ignored (they may be NaN).
        mask : array_like, shape (rows, cols)
            Boolean or real numeric array; non-zero entries are valid pixels.

        Returns
        -------
        UnwrapResult
            Unwrapped phase (float64, radians, NaN outside the mask, read-only), the path
            that ran, the residue count of the check that chose it, and the reason.

        Raises
        ------
        ValueError
            If the arrays are not 2-D of the same shape with at least 2 rows and 2 columns,
            ``wrapped`` is not real or not finite at a valid pixel, or ``mask`` is not
            boolean or finite real numeric. The state is left unchanged.
        EmptyAperture
            If ``mask`` has no valid pixel (a ``ValueError``); the state is left unchanged.

        References
        ----------
        .. [1] J. M. Huntley and H. Saldner, Applied Optics 32(17), 3047-3052 (1993).
        """
        values, valid = _validated_frame(wrapped, mask)
        previous, previous_mask, work = self._phase, self._mask, self._work
        if previous is None or previous_mask is None or work is None:
            return self._spatial(values, valid, "no previous frame", align=False)
        if previous.shape != valid.shape:
            reason = f"frame shape changed from {previous.shape} to {valid.shape}"
            return self._spatial(values, valid, reason, align=False)
        if not np.array_equal(valid, previous_mask):
            reason = f"mask changed (IoU {aperture_iou(valid, previous_mask):.4f})"
            return self._spatial(values, valid, reason, align=True)

        with np.errstate(invalid="ignore"):  # NaN outside the mask: previous is NaN there
            phase = np.subtract(values, previous)
        work.wrap(phase)
        wrap_edges = work.wrap_edges(phase)
        residues = 0  # a residue needs a wrapping edge: skip the loop sums in steady state
        if wrap_edges:
            residues = _residues(*_wrap_counts(phase), work.loops)
        if residues > self._max_residues:
            reason = (
                f"{residues} residues in the frame difference > max_residues={self._max_residues}"
            )
            return self._spatial(values, valid, reason, align=True, residues=residues)
        if wrap_edges > self._max_wrap_edges:
            reason = (
                f"frame-to-frame change crossed +-pi on {wrap_edges} pixel edges > "
                f"max_wrap_edges={self._max_wrap_edges}"
            )
            return self._spatial(values, valid, reason, align=True, residues=residues)

        phase += previous
        phase.flags.writeable = False
        self._phase = phase
        reason = f"smooth change since the previous frame ({wrap_edges} wrapping edges)"
        return UnwrapResult(phase=phase, path="temporal", residues=residues, reason=reason)

    def _spatial(
        self,
        values: NDArray[np.float64],
        valid: NDArray[np.bool_],
        reason: str,
        *,
        align: bool,
        residues: int | None = None,
    ) -> UnwrapResult:
        """Run the spatial method, align it to the previous frame if asked, store it."""
        logger.debug("spatial unwrap: %s", reason)
        if residues is None:
            residues = _count_residues(values, valid)
        phase = _unwrap_with_opencv(values, valid, self._params)
        labels, count = _components(valid)
        reference = self._phase if align else None
        reference_valid = self._mask if align else None
        phase = _shift_components(phase, labels, count, reference, reference_valid)
        phase.flags.writeable = False
        mask_copy = valid.copy()
        mask_copy.flags.writeable = False
        work = self._work
        if work is None or work.shape != mask_copy.shape:
            work = _Workspace(mask_copy.shape)
        work.loops = _loop_mask(mask_copy)
        self._phase, self._mask, self._work = phase, mask_copy, work
        return UnwrapResult(phase=phase, path="spatial", residues=residues, reason=reason)


class _Workspace:
    """Scratch buffers of one frame shape for the temporal step, and the loop mask.

    Reusing the buffers avoids allocating (and page-faulting) several megabytes per frame,
    which costs more than the arithmetic: the same step with fresh temporaries measured
    about three times slower at 1024 x 1024.
    """

    __slots__ = ("_flags", "_pairs", "_single", "_turns", "loops", "shape")

    def __init__(self, shape: tuple[int, int]) -> None:
        rows, cols = shape
        self.shape = (rows, cols)
        self.loops = np.zeros((rows - 1, cols - 1), dtype=np.bool_)
        self._turns = np.empty((rows, cols), dtype=np.float64)
        self._single = np.empty(rows * cols, dtype=np.float32)
        self._pairs = np.empty(rows * cols, dtype=np.float32)
        self._flags = np.empty(rows * cols, dtype=np.bool_)

    def wrap(self, values: NDArray[np.float64]) -> None:
        """Wrap a float64 array of this shape into ``[-pi, pi]`` in place."""
        turns = self._turns
        np.multiply(values, 1.0 / _TWO_PI, out=turns)
        np.rint(turns, out=turns)
        np.multiply(turns, _TWO_PI, out=turns)
        np.subtract(values, turns, out=values)

    def wrap_edges(self, field_: NDArray[np.float64]) -> int:
        """Number of horizontal and vertical pixel edges where a wrapped field jumps by > pi.

        Same decision as :func:`_wrap_counts` (edges touching NaN do not count), computed on
        float32 differences of the flattened field; the horizontal pairs that join the last
        pixel of a row to the first of the next are discarded.
        """
        cols = self.shape[1]
        size = self._single.size
        limit = np.float32(math.pi)
        single = self._single
        np.copyto(single.reshape(self.shape), field_, casting="same_kind")
        count = 0
        for step in (1, cols):
            pairs = self._pairs[: size - step]
            np.subtract(single[step:], single[:-step], out=pairs)
            np.abs(pairs, out=pairs)
            jumps = self._flags[: size - step]
            np.greater(pairs, limit, out=jumps)
            if step == 1:
                jumps[cols - 1 :: cols] = False
            count += int(np.count_nonzero(jumps))
        return count


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


def _wrap(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """``values - 2 pi rint(values / 2 pi)`` in a new array (NaN stays NaN)."""
    turns = np.multiply(values, 1.0 / _TWO_PI)
    np.rint(turns, out=turns)
    turns *= _TWO_PI
    return np.subtract(values, turns, out=turns)


def _wrap_counts(field_: NDArray[np.float64]) -> tuple[NDArray[np.int8], NDArray[np.int8]]:
    """Signed 2 pi wrap counts of the horizontal and vertical differences of a wrapped field.

    ``field_`` must lie in ``[-pi, pi]`` (NaN at invalid pixels); the counts are then -1, 0
    or +1 (the sign of the difference where it exceeds pi in magnitude) and 0 on every edge
    touching a NaN. Shapes ``(rows, cols - 1)`` and ``(rows - 1, cols)``.
    """
    single = field_.astype(np.float32)
    limit = np.float32(math.pi)
    counts = []
    for diff in (single[:, 1:] - single[:, :-1], single[1:, :] - single[:-1, :]):
        up = np.greater(diff, limit).view(np.int8)
        down = np.less(diff, -limit).view(np.int8)
        counts.append(np.subtract(up, down))
    return counts[0], counts[1]


def _count_residues(values: NDArray[np.float64], valid: NDArray[np.bool_]) -> int:
    """Residues of a validated wrapped map inside its mask."""
    wraps_x, wraps_y = _wrap_counts(_wrap(np.where(valid, values, np.nan)))
    return _residues(wraps_x, wraps_y, _loop_mask(valid))


def _residues(
    wraps_x: NDArray[np.int8], wraps_y: NDArray[np.int8], loops: NDArray[np.bool_]
) -> int:
    """Count loops (valid per ``loops``) with a non-zero circulation of wrap counts.

    The raw differences around a loop cancel, so the sum of the wrapped differences is
    ``-2 pi`` times the sum of the wrap counts: a residue is a loop where that sum is not 0.
    """
    circulation = wraps_x[:-1, :] - wraps_x[1:, :]
    circulation += wraps_y[:, 1:]
    circulation -= wraps_y[:, :-1]
    return int(np.count_nonzero(np.logical_and(circulation, loops)))


def _loop_mask(valid: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """2 x 2 loops whose four pixels are valid, shape (rows - 1, cols - 1)."""
    loops = valid[:-1, :-1] & valid[1:, :-1]
    loops &= valid[:-1, 1:]
    loops &= valid[1:, 1:]
    return loops


def _components(valid: NDArray[np.bool_]) -> tuple[NDArray[np.int32], int]:
    """4-connected components of the mask: labels (0 = invalid) and their number."""
    count, labels = cv2.connectedComponents(
        valid.astype(np.uint8), connectivity=4, ltype=cv2.CV_32S
    )
    return np.asarray(labels, dtype=np.int32), int(count) - 1


def _shift_components(
    phase: NDArray[np.float64],
    labels: NDArray[np.int32],
    count: int,
    reference: NDArray[np.float64] | None,
    reference_valid: NDArray[np.bool_] | None,
) -> NDArray[np.float64]:
    """Shift each component by 2 pi k so the median of (phase - reference) is in [-pi, pi).

    Without a reference, or for a component sharing no valid pixel with it, the median of
    the phase itself is used.
    """
    index = np.arange(1, count + 1)
    medians = _label_medians(phase, labels, index)
    if reference is not None and reference_valid is not None:
        shared_labels = np.where(reference_valid, labels, 0)
        shared = np.bincount(shared_labels.ravel(), minlength=count + 1)[1:] > 0
        if shared.any():
            with np.errstate(invalid="ignore"):
                offsets = phase - reference
            medians[shared] = _label_medians(offsets, shared_labels, index[shared])
    turns = np.floor((medians + math.pi) / _TWO_PI)
    if not turns.any():
        return phase
    shift = np.concatenate(([0.0], _TWO_PI * turns))
    return phase - shift[labels]


def _label_medians(
    values: NDArray[np.float64], labels: NDArray[np.int32], index: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Median of ``values`` over each label in ``index`` (every label must have pixels)."""
    if index.size == 1:  # the usual single pupil: a plain median is ~10x faster
        return np.array([np.median(values[labels == index[0]])])
    return np.asarray(ndimage.median(values, labels, index), dtype=np.float64).reshape(-1)


def _is_real(value: object) -> bool:
    """True for real numbers other than booleans."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _real_array(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """``value`` as a float64 array, refusing booleans, complex and non-numeric data."""
    array = np.asarray(value)
    if array.dtype == np.bool_ or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise ValueError(f"{name} must be real numeric, got dtype {array.dtype}")
    return np.asarray(array, dtype=np.float64)


def _validated_frame(
    wrapped: ArrayLike, mask: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Check a wrapped map and its mask; return float64 values and a boolean mask."""
    values = _real_array(wrapped, "wrapped")
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


def _validated_limit(value: int, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    return int(value)
