"""A cheap per-frame check that the aperture has not moved, so full detection runs only on change.

Full detection (:func:`~wavestack.pipeline.aperture.detect.detect_aperture`: half-way threshold, morphology,
component labelling, holes, topology) costs tens of milliseconds at 1024 x 1024, more than the
rest of a frame's work. While the aperture holds still that work is wasted: the station only
needs to know *whether* the aperture changed. The watch answers that on a block-averaged copy:

1. average the signal map (modulation or fringe contrast) over ``factor x factor`` blocks
   (``cv2.resize`` with ``INTER_AREA``);
2. threshold it at the level the full detection used for the reference;
3. compare with the reference mask averaged the same way (a block counts as inside when more
   than half its pixels are), by intersection over union.

Averaging first makes the check blind to speckle and dropouts smaller than a block, which the full
detection removes anyway, and costs about ``1 / factor**2`` of a full-resolution pass. A real
change (the optic moved, a new obscuration, a different mask) changes whole blocks and drops the
IoU below the threshold; then the caller runs the full detection and rebuilds.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class WatchVerdict:
    """Result of :meth:`ApertureWatch.check`.

    Attributes
    ----------
    changed : bool
        True when the block-averaged aperture no longer matches the reference.
    iou : float
        Intersection over union of the block masks, in [0, 1].
    """

    changed: bool
    iou: float


def _block_average(values: NDArray[np.generic], factor: int) -> NDArray[np.floating]:
    rows, cols = values.shape
    small = (max(1, cols // factor), max(1, rows // factor))
    if values.dtype not in (np.float32, np.float64):  # OpenCV averages floats without a copy
        values = values.astype(np.float32)
    return cv2.resize(values, small, interpolation=cv2.INTER_AREA)


class ApertureWatch:
    """Watch a stream of signal maps for a change of the aperture found in the first.

    Parameters
    ----------
    reference_mask : ndarray of bool, shape (rows, cols)
        The aperture the current fitter was built for.
    threshold : float
        The signal level the full detection used (``DetectedAperture.threshold``), map units.
    factor : int
        Block size in pixels (>= 1). Default 4: 1024 x 1024 becomes 256 x 256.
    iou_threshold : float
        Smallest block IoU that counts as unchanged, in (0, 1]. Default 0.95: the block masks
        differ along the rim by quantisation alone, so this is looser than the full-resolution
        tracker's 0.98.

    Raises
    ------
    ValueError
        If the mask is not 2-D or empty, ``factor`` < 1, or ``iou_threshold`` is outside (0, 1].
    """

    def __init__(
        self,
        reference_mask: ArrayLike,
        threshold: float,
        *,
        factor: int = 4,
        iou_threshold: float = 0.95,
    ) -> None:
        mask = np.asarray(reference_mask, dtype=bool)
        if mask.ndim != 2 or not mask.any():
            raise ValueError(f"reference_mask must be a non-empty 2-D mask, got shape {mask.shape}")
        if factor < 1:
            raise ValueError(f"factor is {factor}; expected an integer >= 1")
        if not 0.0 < iou_threshold <= 1.0:
            raise ValueError(f"iou_threshold is {iou_threshold}; expected a number in (0, 1]")
        self._shape = mask.shape
        self._threshold = float(threshold)
        self._factor = int(factor)
        self._iou_threshold = float(iou_threshold)
        self._reference_blocks = _block_average(mask, factor) > 0.5
        self._reference_count = int(self._reference_blocks.sum())

    @property
    def shape(self) -> tuple[int, int]:
        """Shape of the maps this watch accepts."""
        return self._shape

    def check(self, signal_map: ArrayLike) -> WatchVerdict:
        """Does this signal map still show the reference aperture?

        Parameters
        ----------
        signal_map : array_like, shape (rows, cols)
            Modulation or fringe-contrast map of the current frame; NaN counts as outside.

        Returns
        -------
        WatchVerdict
            ``changed`` is True for a different map shape or a block IoU below the threshold.
        """
        values = np.asarray(signal_map)
        if values.shape != self._shape:
            return WatchVerdict(True, 0.0)
        blocks = _block_average(values, self._factor) > self._threshold  # NaN compares False
        intersection = int(np.count_nonzero(blocks & self._reference_blocks))
        union = int(np.count_nonzero(blocks)) + self._reference_count - intersection
        iou = intersection / union if union else 0.0
        return WatchVerdict(iou < self._iou_threshold, iou)
