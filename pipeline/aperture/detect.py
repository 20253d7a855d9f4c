"""Find the valid aperture in a modulation (or intensity) map.

The mirror shows up in a modulation map as a bright region; around it there is a dim speckled
halo and inside it small dark dropouts (dust, speckle) and possibly a real central obscuration.
:func:`detect_aperture` turns the map into a validity mask in five steps and hands the mask to
:meth:`Aperture.from_mask <wavestack.pipeline.aperture.region.Aperture.from_mask>`:

1. threshold: valid where ``map > threshold``; NaN pixels never pass. Unless a threshold is given,
   it is the half-way level between the disk and the halo (:mod:`.levels`): a first pass at Otsu's
   threshold [1]_ (steps 1-4) gives a coarse aperture, robust medians inside and outside it give
   the two levels, and the map, smoothed by a Gaussian of ``smooth_sigma_px`` (which does not move
   a half-way edge, but averages halo speckle touching the rim below it), is thresholded half way
   between the disk level and the *local* halo level (a map: a halo touching the rim on one
   side is brighter there, see :func:`~wavestack.pipeline.aperture.levels.local_threshold`);
2. morphological opening, then closing, with elliptical kernels [2]_ (removes speckle, bridges
   one- or two-pixel gaps);
3. 8-connected components [3]_: keep the largest, or all of at least ``min_component_px``;
4. holes (4-connected background regions not reaching the image border, the complement of
   8-connectivity) smaller than ``fill_dropouts_below_px`` are filled; larger ones are real
   obscurations and stay.

The aperture is the geometric pupil, not the per-pixel validity of this one map: NaN pixels
and dark dropouts inside the pupil are filled when they are small enough.

Comparing and tracking apertures from frame to frame is :mod:`wavestack.pipeline.aperture.compare`.

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
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import int_at_least, is_finite_real, real_at_least
from .levels import ModulationLevels, local_threshold, modulation_levels, smoothed
from .region import Aperture, EmptyAperture

__all__ = ["DetectedAperture", "DetectionSettings", "detect_aperture"]

logger = logging.getLogger(__name__)

_KEEP_CHOICES = ("largest", "all")
_RULES = ("midpoint", "otsu")


@dataclass(frozen=True)
class DetectionSettings:
    """Parameters of :func:`detect_aperture`.

    Attributes
    ----------
    threshold : float or None
        Absolute threshold in map units: pixels with ``map > threshold`` are valid. None
        (default) finds one by ``rule``, see :func:`detect_aperture`.
    rule : {"midpoint", "otsu"}
        With ``threshold=None``: ``"midpoint"`` (default) thresholds the smoothed map half way
        between the disk's and the halo's levels (the edge of the optic, see :mod:`.levels`);
        ``"otsu"`` stops at Otsu's threshold on the raw map (the detection before this rule).
    smooth_sigma_px : float
        Gaussian sigma, pixels, of the smoothing before the half-way threshold (``"midpoint"``
        rule only); of the order of the speckle grain. 0 skips it. Default 1.5.
    edge_margin_px : int
        Distance from the coarse edge to the pixels the disk and halo levels are taken from
        (``"midpoint"`` rule), at least the half-width of the map's edge response. Default 3
        (a modulation map); a local-contrast map needs half its box plus that.
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
    rule: str = "midpoint"
    smooth_sigma_px: float = 1.5
    edge_margin_px: int = 3

    def __post_init__(self) -> None:
        if self.threshold is not None and not is_finite_real(self.threshold):
            raise ValueError(
                f"threshold is {self.threshold!r}; expected None (Otsu) or a finite real "
                "number in map units"
            )
        int_at_least(self.open_radius_px, "open_radius_px", 0, voice="is")
        int_at_least(self.close_radius_px, "close_radius_px", 0, voice="is")
        int_at_least(self.fill_dropouts_below_px, "fill_dropouts_below_px", 0, voice="is")
        int_at_least(self.min_component_px, "min_component_px", 1, voice="is")
        if self.keep not in _KEEP_CHOICES:
            raise ValueError(f"keep is {self.keep!r}; expected 'largest' or 'all'")
        if self.rule not in _RULES:
            raise ValueError(f"rule is {self.rule!r}; expected 'midpoint' or 'otsu'")
        real_at_least(self.smooth_sigma_px, "smooth_sigma_px", 0.0, unit="pixels", voice="is")
        int_at_least(self.edge_margin_px, "edge_margin_px", 1, voice="is")


@dataclass(frozen=True, eq=False)
class DetectedAperture:
    """Result of :func:`detect_aperture`.

    Attributes
    ----------
    aperture : Aperture
        The detected aperture.
    threshold : float
        The threshold applied, in map units (valid where ``map > threshold``); under the
        ``"midpoint"`` rule the global half-way level, the local threshold map being half way
        to the local halo level (equal to it where the halo is uniform).
    filled_dropouts : int
        Number of holes filled (smaller than ``fill_dropouts_below_px``).
    removed_components : int
        Number of 8-connected components dropped after the morphology (speckle, halo pieces).
    levels : ModulationLevels or None
        The disk and halo levels the half-way threshold came from (``"midpoint"`` rule), else
        None.
    """

    aperture: Aperture
    threshold: float
    filled_dropouts: int
    removed_components: int
    levels: ModulationLevels | None = None


def detect_aperture(
    signal_map: ArrayLike,
    settings: DetectionSettings = DetectionSettings(),
    *,
    min_hole_area_px: float = 4.0,
) -> DetectedAperture:
    """Detect the valid aperture (the bright pupil) in a modulation or intensity map.

    With ``settings.threshold = None`` the first threshold is Otsu's [1]_: the finite values are
    rescaled linearly to 8 bits, ``q = round(255 (v - lo) / (hi - lo))`` with ``lo``, ``hi``
    their minimum and maximum, ``cv2.threshold(..., THRESH_OTSU)`` returns the level ``t``
    separating ``q <= t`` from ``q > t``, and the threshold in map units is the class boundary
    ``lo + (t + 0.5) (hi - lo) / 255``. Either way the mask is then ``map > threshold`` on the
    original values. With the ``"midpoint"`` rule (default) that aperture is only a coarse one:
    the disk and halo levels are the medians inside and outside it
    (:func:`~wavestack.pipeline.aperture.levels.modulation_levels`) and steps 1-4 run again on
    the map smoothed by ``settings.smooth_sigma_px`` at the half-way level, which is the
    threshold reported. The edge is then the optic's own (the 50 % point of its edge
    response) to within the pixel grid; sub-pixel edge points and a fitted circle are
    :func:`~wavestack.pipeline.aperture.edge_circle.fit_edge_circle`. A map whose inside is not
    above its outside keeps Otsu's aperture.

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
    real_at_least(min_hole_area_px, "min_hole_area_px", 0.0, unit="pixels", voice="is")
    values = _validated_map(signal_map)
    lo, hi, has_nan = _finite_range(values)
    levels = None
    if settings.threshold is not None:
        threshold = float(settings.threshold)
        mask, filled, removed = _clean_mask(values, threshold, settings)
    else:
        threshold = _otsu_threshold(values, lo, hi, has_nan)
        mask, filled, removed = _clean_mask(values, threshold, settings)
        if settings.rule == "midpoint":
            margin = settings.edge_margin_px
            levels = modulation_levels(values, mask, margin)
            if levels.disk > levels.halo:
                threshold = levels.midpoint
                mask, filled, removed = _clean_mask(
                    smoothed(values, settings.smooth_sigma_px),
                    local_threshold(values, mask, levels, margin), settings,
                )
            else:  # no plateau above its surroundings: keep Otsu's answer
                levels = None
    aperture = Aperture.from_mask(mask.view(np.bool_), min_hole_area_px=min_hole_area_px)
    logger.debug(
        "aperture detected: threshold %.6g, %d components removed, %d dropouts filled; %s",
        threshold,
        removed,
        filled,
        aperture.describe(),
    )
    return DetectedAperture(aperture, threshold, filled, removed, levels)


def _clean_mask(
    values: NDArray[np.generic], threshold: float | NDArray[np.float32], settings: DetectionSettings
) -> tuple[NDArray[np.uint8], int, int]:
    """Steps 1-4: threshold (a level or a map of levels), open, close, select components, fill holes.

    Returns the mask (uint8, 1 = valid), the holes filled and the components removed.
    """
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
    return mask, filled, removed


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
