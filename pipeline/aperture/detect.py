"""Find the valid aperture in a modulation (or intensity) map, and track it from frame to frame.

The mirror shows up in a modulation map as a bright region; around it there is a dim speckled
halo and inside it small dark dropouts (dust, speckle) and possibly a real central obscuration.
:func:`detect_aperture` turns the map into a validity mask in five steps and hands the mask to
:meth:`Aperture.from_mask <wavestack.pipeline.aperture.region.Aperture.from_mask>`:

1. threshold: valid where ``map > threshold`` (Otsu's threshold [1]_ unless one is given);
   NaN pixels never pass;
2. morphological opening, then closing, with elliptical kernels [2]_ (removes speckle, bridges
   one- or two-pixel gaps);
3. 8-connected components [3]_: keep the largest, or all of at least ``min_component_px``;
4. holes (4-connected background regions not reaching the image border, the complement of
   8-connectivity) smaller than ``fill_dropouts_below_px`` are filled; larger ones are real
   obscurations and stay.

The aperture is the geometric pupil, not the per-pixel validity of this one map: NaN pixels
and dark dropouts inside the pupil are filled when they are small enough.

:func:`aperture_iou` compares two apertures and :class:`ApertureTracker` decides from it
whether a fitter built for an earlier aperture can be reused.

References
----------
.. [1] N. Otsu, "A threshold selection method from gray-level histograms", IEEE Trans.
   Systems, Man, and Cybernetics 9(1), 62-66 (1979).
.. [2] P. Soille, *Morphological Image Analysis*, 2nd ed., Springer (2003), ch. 4 and 8.
.. [3] OpenCV documentation: ``cv2.threshold`` (``THRESH_OTSU``), ``cv2.morphologyEx``,
   ``cv2.getStructuringElement`` (``MORPH_ELLIPSE``), ``cv2.connectedComponentsWithStats``.
"""

from __future__ import annotations

import logging
import math
import numbers
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .region import Aperture, EmptyAperture

__all__ = [
    "ApertureChange",
    "ApertureTracker",
    "DetectedAperture",
    "DetectionSettings",
    "aperture_iou",
    "detect_aperture",
]

logger = logging.getLogger(__name__)

_KEEP_CHOICES = ("largest", "all")


def _check_int(name: str, value: object, minimum: int) -> None:
    """Raise ValueError unless ``value`` is an integer (not a bool) >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} is {value!r}; expected an integer >= {minimum}")


@dataclass(frozen=True)
class DetectionSettings:
    """Parameters of :func:`detect_aperture`.

    Attributes
    ----------
    threshold : float or None
        Absolute threshold in map units: pixels with ``map > threshold`` are valid. None
        (default) uses Otsu's threshold, see :func:`detect_aperture`.
    open_radius_px : int
        Radius in pixels of the elliptical opening kernel (size ``2 r + 1``); removes bright
        speckle narrower than the kernel. 0 skips the opening. Default 2.
    close_radius_px : int
        Radius in pixels of the elliptical closing kernel; bridges dark gaps narrower than the
        kernel. 0 skips the closing. Default 2.
    fill_dropouts_below_px : int
        Holes with fewer pixels than this are filled (dust, speckle dropouts); larger holes are
        real obscurations and are kept. 0 fills nothing. Default 200.
    keep : {"largest", "all"}
        Keep the largest component, or every component of at least ``min_component_px``.
    min_component_px : int
        Smallest component kept, in pixels (also applies to the largest one). Default 500.

    Raises
    ------
    ValueError
        If a field is out of range; the message names it.
    """

    threshold: float | None = None
    open_radius_px: int = 2
    close_radius_px: int = 2
    fill_dropouts_below_px: int = 200
    keep: str = "largest"
    min_component_px: int = 500

    def __post_init__(self) -> None:
        if self.threshold is not None and (
            isinstance(self.threshold, bool)
            or not isinstance(self.threshold, numbers.Real)
            or not math.isfinite(self.threshold)
        ):
            raise ValueError(
                f"threshold is {self.threshold!r}; expected None (Otsu) or a finite real "
                "number in map units"
            )
        _check_int("open_radius_px", self.open_radius_px, 0)
        _check_int("close_radius_px", self.close_radius_px, 0)
        _check_int("fill_dropouts_below_px", self.fill_dropouts_below_px, 0)
        _check_int("min_component_px", self.min_component_px, 1)
        if self.keep not in _KEEP_CHOICES:
            raise ValueError(f"keep is {self.keep!r}; expected 'largest' or 'all'")


@dataclass(frozen=True, eq=False)
class DetectedAperture:
    """Result of :func:`detect_aperture`.

    Attributes
    ----------
    aperture : Aperture
        The detected aperture.
    threshold : float
        The threshold applied, in map units (valid where ``map > threshold``).
    filled_dropouts : int
        Number of holes filled (smaller than ``fill_dropouts_below_px``).
    removed_components : int
        Number of 8-connected components dropped after the morphology (speckle, halo pieces).
    """

    aperture: Aperture
    threshold: float
    filled_dropouts: int
    removed_components: int


@dataclass(frozen=True)
class ApertureChange:
    """Verdict of :meth:`ApertureTracker.update`.

    Attributes
    ----------
    changed : bool
        True when a fitter built for the reference aperture must not be reused.
    iou : float
        Intersection over union with the reference aperture (0.0 when there is none or the
        shapes differ).
    reason : str
        Human-readable explanation.
    """

    changed: bool
    iou: float
    reason: str


def detect_aperture(
    signal_map: ArrayLike,
    settings: DetectionSettings = DetectionSettings(),
    *,
    min_hole_area_px: float = 4.0,
) -> DetectedAperture:
    """Detect the valid aperture (the bright pupil) in a modulation or intensity map.

    With ``settings.threshold = None`` the threshold is Otsu's [1]_: the finite values are
    rescaled linearly to 8 bits, ``q = round(255 (v - lo) / (hi - lo))`` with ``lo``, ``hi``
    their minimum and maximum, ``cv2.threshold(..., THRESH_OTSU)`` returns the level ``t``
    separating ``q <= t`` from ``q > t``, and the threshold in map units is the class boundary
    ``lo + (t + 0.5) (hi - lo) / 255``. Either way the mask is then ``map > threshold`` on the
    original values, so the reported threshold is exactly the one applied.

    Parameters
    ----------
    signal_map : array_like, shape (rows, cols)
        Modulation or intensity map, real (bool, integer or float) values; NaN marks pixels
        without data (never valid by themselves, but filled like any dropout if small and
        inside the pupil). Infinite values are rejected. Not modified.
    settings : DetectionSettings, optional
        Threshold, morphology and component selection.
    min_hole_area_px : float, optional
        Passed to :meth:`Aperture.from_mask`: holes that remain (not filled) and are smaller
        than this do not count in the topology. Pixels, default 4.

    Returns
    -------
    DetectedAperture
        The aperture, the threshold used and the numbers of filled holes and dropped
        components.

    Raises
    ------
    ValueError
        If ``signal_map`` is not a 2-D real array with rows, cols >= 1 and no infinite value,
        or ``settings`` is not a :class:`DetectionSettings`, or ``min_hole_area_px`` is not
        a finite number >= 0.
    EmptyAperture
        If the map has no finite value, is constant (no Otsu threshold), or no component of at
        least ``settings.min_component_px`` pixels survives.

    References
    ----------
    .. [1] N. Otsu, IEEE Trans. SMC 9(1), 62-66 (1979).
    """
    if not isinstance(settings, DetectionSettings):
        raise ValueError(
            f"settings is {type(settings).__name__}; expected a DetectionSettings instance"
        )
    if (
        isinstance(min_hole_area_px, bool)
        or not isinstance(min_hole_area_px, numbers.Real)
        or not 0.0 <= float(min_hole_area_px) < math.inf
    ):
        raise ValueError(
            f"min_hole_area_px is {min_hole_area_px!r}; expected a finite number >= 0 (pixels)"
        )
    values = _validated_map(signal_map)
    lo, hi, has_nan = _finite_range(values)
    if settings.threshold is not None:
        threshold = float(settings.threshold)
    else:
        threshold = _otsu_threshold(values, lo, hi, has_nan)
    mask = np.greater(values, threshold).view(np.uint8)
    if settings.open_radius_px:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _ellipse(settings.open_radius_px))
    if settings.close_radius_px:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _ellipse(settings.close_radius_px))
    # Everything below happens in bounding boxes: outside them the mask is empty, so a
    # background region touching the edge of a box is connected to the image border.
    box = _bounding_box(mask)
    selected, removed = _select_components(np.ascontiguousarray(mask[box]), settings)
    inner = _bounding_box(selected)
    pupil = np.ascontiguousarray(selected[inner])
    filled = _fill_small_holes(pupil, settings.fill_dropouts_below_px)
    mask = np.zeros(values.shape, dtype=np.uint8)
    mask[box][inner] = pupil
    aperture = Aperture.from_mask(mask.view(np.bool_), min_hole_area_px=min_hole_area_px)
    logger.debug(
        "aperture detected: threshold %.6g, %d components removed, %d dropouts filled; %s",
        threshold,
        removed,
        filled,
        aperture.describe(),
    )
    return DetectedAperture(aperture, threshold, filled, removed)


def aperture_iou(a: Aperture | ArrayLike, b: Aperture | ArrayLike) -> float:
    """Intersection over union (Jaccard index) of two apertures or masks.

    Parameters
    ----------
    a, b : Aperture or array_like, shape (rows, cols)
        Apertures, or masks (bool or finite real; non-zero = valid) of the same shape.

    Returns
    -------
    float
        ``|A & B| / |A | B|`` in [0, 1]: 1 for identical masks, 0 for disjoint ones.

    Raises
    ------
    ValueError
        If a mask is not a 2-D bool or finite real array, the shapes differ, or both masks are
        empty (IoU undefined).

    References
    ----------
    .. [1] P. Jaccard, "The distribution of the flora in the alpine zone", New Phytologist
       11(2), 37-50 (1912).
    """
    mask_a = _as_mask("a", a)
    mask_b = _as_mask("b", b)
    if mask_a.shape != mask_b.shape:
        raise ValueError(
            f"a has shape {mask_a.shape} and b has shape {mask_b.shape}; expected equal shapes"
        )
    union = int(np.count_nonzero(mask_a | mask_b))
    if union == 0:
        raise ValueError("a and b are both empty; expected at least one valid pixel")
    return int(np.count_nonzero(mask_a & mask_b)) / union


def compare_apertures(reference: Aperture, aperture: Aperture, iou_threshold: float) -> ApertureChange:
    """Is ``aperture`` the same aperture as ``reference`` for a fitter built on the latter?

    Parameters
    ----------
    reference, aperture : Aperture
    iou_threshold : float
        Smallest intersection over union that counts as the same aperture, in (0, 1].

    Returns
    -------
    ApertureChange
        ``changed`` when the mask shapes differ, the topology or the number of components
        differs, or the IoU is below ``iou_threshold``; ``reason`` says which.
    """
    if reference.shape != aperture.shape:
        return ApertureChange(True, 0.0, f"mask shape changed from {reference.shape} to {aperture.shape}")
    iou = aperture_iou(reference, aperture)
    if (reference.topology, reference.components) != (aperture.topology, aperture.components):
        return ApertureChange(
            True, iou, f"topology changed from {reference.describe()!r} to {aperture.describe()!r}"
        )
    if iou < iou_threshold:
        return ApertureChange(True, iou, f"IoU {iou:.4f} below threshold {iou_threshold:g}")
    return ApertureChange(False, iou, f"IoU {iou:.4f} >= threshold {iou_threshold:g}")


class ApertureTracker:
    """Decide, frame after frame, whether a fitter built for an earlier aperture is reusable.

    The tracker holds a reference aperture: the one the current fitter was built for. Each
    :meth:`update` compares the new aperture with it; when the change is too large the new
    aperture becomes the reference (build a new fitter). An unchanged verdict leaves the
    reference alone, so a slow drift accumulates until it crosses the threshold. Not
    thread-safe.

    Parameters
    ----------
    iou_threshold : float, optional
        Smallest intersection over union with the reference for which the aperture counts as
        unchanged; must be in (0, 1]. Default 0.98.

    Raises
    ------
    ValueError
        If ``iou_threshold`` is not a real number in (0, 1].
    """

    def __init__(self, iou_threshold: float = 0.98) -> None:
        if (
            isinstance(iou_threshold, bool)
            or not isinstance(iou_threshold, numbers.Real)
            or not 0.0 < float(iou_threshold) <= 1.0
        ):
            raise ValueError(f"iou_threshold is {iou_threshold!r}; expected a number in (0, 1]")
        self._iou_threshold = float(iou_threshold)
        self._reference: Aperture | None = None

    @property
    def iou_threshold(self) -> float:
        """Smallest IoU with the reference that counts as unchanged."""
        return self._iou_threshold

    @property
    def reference(self) -> Aperture | None:
        """The aperture the current fitter was built for (None before the first update)."""
        return self._reference

    def reset(self) -> None:
        """Forget the reference; the next :meth:`update` reports a change."""
        self._reference = None

    def update(self, aperture: Aperture) -> ApertureChange:
        """Compare a new aperture with the reference.

        Parameters
        ----------
        aperture : Aperture
            Aperture of the current frame.

        Returns
        -------
        ApertureChange
            ``changed`` is True on the first call (or after :meth:`reset`), when the mask
            shape, the topology or the number of components differs, or when the IoU with the
            reference is below ``iou_threshold``; the new aperture then becomes the
            reference.

        Raises
        ------
        ValueError
            If ``aperture`` is not an :class:`Aperture`.
        """
        if not isinstance(aperture, Aperture):
            raise ValueError(f"aperture is {type(aperture).__name__}; expected an Aperture")
        reference = self._reference
        if reference is None:
            change = ApertureChange(True, 0.0, "no reference aperture yet")
        else:
            change = compare_apertures(reference, aperture, self._iou_threshold)
        if change.changed:
            self._reference = aperture
        return change


def _validated_map(signal_map: ArrayLike) -> NDArray[np.generic]:
    """Check the map and return it as an array (no copy when possible)."""
    expected = "expected a 2-D array of real numbers (NaN allowed) with rows, cols >= 1"
    try:
        values = np.asarray(signal_map)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"signal_map could not be converted to an array ({exc}); {expected}"
        ) from exc
    if values.ndim != 2 or values.size == 0 or values.dtype.kind not in "biuf":
        raise ValueError(f"signal_map has shape {values.shape}, dtype {values.dtype}; {expected}")
    if values.dtype.kind == "b":
        return values.view(np.uint8)
    return values


def _as_mask(name: str, value: Aperture | ArrayLike) -> NDArray[np.bool_]:
    """The mask of an Aperture, or a checked 2-D array as booleans (non-zero = valid)."""
    if isinstance(value, Aperture):
        return value.mask
    expected = "expected an Aperture or a 2-D array of booleans or finite real numbers"
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} could not be converted to an array ({exc}); {expected}") from exc
    if array.ndim != 2 or array.dtype.kind not in "biuf":
        raise ValueError(f"{name} has shape {array.shape}, dtype {array.dtype}; {expected}")
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise ValueError(f"{name} has NaN or infinite entries; {expected}")
    return array != 0


def _finite_range(values: NDArray[np.generic]) -> tuple[float, float, bool]:
    """Minimum and maximum of the finite values, and whether the map has NaN."""
    lo, hi = np.min(values), np.max(values)
    if values.dtype.kind != "f" or (np.isfinite(lo) and np.isfinite(hi)):
        return float(lo), float(hi), False
    if np.isinf(values).any():
        raise ValueError("signal_map has infinite values; expected finite values or NaN")
    if np.isnan(values).all():
        raise EmptyAperture(f"signal_map of shape {values.shape} has no finite value")
    return float(np.nanmin(values)), float(np.nanmax(values)), True


def _otsu_threshold(values: NDArray[np.generic], lo: float, hi: float, has_nan: bool) -> float:
    """Otsu threshold in map units from an 8-bit rescaled copy of the finite values."""
    if hi <= lo:
        raise EmptyAperture(f"signal_map is constant ({lo:g}); Otsu's threshold is undefined")
    finite = values[~np.isnan(values)].reshape(1, -1) if has_nan else values
    if finite.dtype not in (np.uint8, np.uint16, np.int16, np.int32, np.float32, np.float64):
        finite = finite.astype(np.float64)
    scale = 255.0 / (hi - lo)
    eight_bit = cv2.convertScaleAbs(np.ascontiguousarray(finite), alpha=scale, beta=-lo * scale)
    level, _ = cv2.threshold(eight_bit, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    return lo + (float(level) + 0.5) / scale


def _ellipse(radius: int) -> NDArray[np.uint8]:
    """Elliptical (disk) structuring element of size 2 radius + 1."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _bounding_box(mask: NDArray[np.uint8]) -> tuple[slice, slice]:
    """Row and column slices of the smallest box holding every non-zero pixel."""
    x, y, w, h = cv2.boundingRect(mask)
    if w == 0:
        raise EmptyAperture("no pixel above the threshold survives the morphological opening")
    return slice(y, y + h), slice(x, x + w)


def _select_components(
    mask: NDArray[np.uint8], settings: DetectionSettings
) -> tuple[NDArray[np.uint8], int]:
    """Keep the components ``settings`` asks for; return the new mask and how many were dropped."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask, connectivity=8, ltype=cv2.CV_32S
    )
    areas = stats[1:, cv2.CC_STAT_AREA]
    kept = np.flatnonzero(areas >= settings.min_component_px) + 1
    if settings.keep == "largest" and kept.size:
        kept = kept[[int(np.argmax(areas[kept - 1]))]]
    if kept.size == 0:
        largest = int(areas.max()) if areas.size else 0
        raise EmptyAperture(
            f"no component of at least min_component_px={settings.min_component_px} pixels "
            f"(largest: {largest})"
        )
    removed = int(areas.size - kept.size)
    if settings.keep == "largest":
        mask = cv2.compare(labels, int(kept[0]), cv2.CMP_EQ) & 1
    else:
        dropped = np.setdiff1d(np.arange(1, count), kept)
        for label in dropped:
            x, y, w, h = stats[label, :4]
            window = mask[y : y + h, x : x + w]
            window[labels[y : y + h, x : x + w] == label] = 0
    return mask, removed


def _fill_small_holes(mask: NDArray[np.uint8], below_px: int) -> int:
    """Fill, in place, holes of fewer than ``below_px`` pixels; return how many were filled.

    The background reachable from the border is flood-filled (4-connected) from a one-pixel
    frame; what stays background are the holes. They are labelled (4-connectivity) and their
    areas counted from their pixels only, which is cheaper than a full-image statistics pass.
    """
    if below_px <= 0:
        return 0
    framed = cv2.copyMakeBorder(mask, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    cv2.floodFill(framed, None, (0, 0), 1, flags=4)
    holes = 1 - framed[1:-1, 1:-1]
    if not cv2.countNonZero(holes):
        return 0
    count, labels = cv2.connectedComponents(holes, connectivity=4, ltype=cv2.CV_32S)
    cols, rows = cv2.findNonZero(holes).reshape(-1, 2).T
    hole_of_pixel = labels[rows, cols]
    small = np.bincount(hole_of_pixel, minlength=count) < below_px
    small[0] = False  # label 0 is everything that is not a hole
    fill = small[hole_of_pixel]
    mask[rows[fill], cols[fill]] = 1
    return int(np.count_nonzero(small))
