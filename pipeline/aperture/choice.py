"""The aperture a measurement is analysed on: detected, a fitted circle, or the user's mask.

Interferometer software gives the same three choices: the aperture as detected from the data
(any shape; the default where the shape is not known), a circle fitted to the detected edge (for
optics known to be round: its centre and radius come from the whole rim, not its outermost
pixels), or a mask the user draws or loads. Whichever is chosen, the edge circle fitted to the
detection (:func:`~wavestack.pipeline.aperture.edge_circle.fit_edge_circle`) is reported with its
uncertainty when the aperture is round enough to give one.

The detected aperture is cut to that circle when the circle holds all of it but a sliver: at most
:data:`EDGE_SLIVER` of its pixels lie outside. Such a sliver is halo the detection joined at the
rim, typically where the rim meets the frame's border (the signal's filter there reaches the disk
from a halo strip thinner than its support): on the bundled carrier frame 0.9 % of the detected
pixels, a bump 15 px beyond the 284.5 px edge that made the enclosing circle, and so the fit's
pupil, 295 px. An aperture the circle does not hold (not round: a rectangle, a strip) is kept as
detected. The rule is ours, not a source's: a round optic's own edge bounds its pixels, and a
sliver beyond it is not the optic.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .detect import DetectedAperture, DetectionSettings, detect_aperture
from .edge_circle import EdgeCircle, EdgeFitError, fit_edge_circle
from .region import Aperture

__all__ = ["APERTURE_CHOICES", "EDGE_SLIVER", "ChosenAperture", "choose_aperture"]

logger = logging.getLogger(__name__)

APERTURE_CHOICES = ("detected", "circle")
#: Largest share of a detected aperture outside its edge circle that is cut off as halo (module notes).
EDGE_SLIVER = 0.02


@dataclass(frozen=True, eq=False)
class ChosenAperture:
    """The aperture used and how it was chosen.

    Attributes
    ----------
    aperture : Aperture
        The aperture to unwrap and fit on.
    choice : str
        ``"detected"``, ``"circle"`` or ``"mask"`` (given by the user).
    edge : EdgeCircle or None
        The circle fitted to the detected edge (centre, radius and their uncertainties, pixels),
        None for a user mask or where no circle fits the detection.
    detected : DetectedAperture or None
        The detection (None for a user mask).
    """

    aperture: Aperture
    choice: str
    edge: EdgeCircle | None
    detected: DetectedAperture | None


def choose_aperture(
    signal_map: NDArray,
    choice: str | ArrayLike = "detected",
    detection: DetectionSettings = DetectionSettings(),
) -> ChosenAperture:
    """Find the aperture of a modulation (or fringe-contrast) map by one of the three choices.

    Parameters
    ----------
    signal_map : NDArray, shape (rows, cols)
        Modulation or local fringe-contrast map.
    choice : {"detected", "circle"} or array_like of shape (rows, cols)
        ``"detected"``: :func:`detect_aperture` (any shape), cut to its edge circle when that holds
        all but a sliver of it (module notes). ``"circle"``: the pixels whose
        centres lie inside the circle fitted to the detected edge, less the detection's holes
        (real obscurations). An array: the user's mask (non-zero = valid).
    detection : DetectionSettings
        How the aperture is detected.

    Returns
    -------
    ChosenAperture

    Raises
    ------
    ValueError
        If ``choice`` is an unknown name or a mask of another shape than the map; if ``"circle"``
        is asked for and no circle fits the edge (the message says so).

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[:120, :120]
    >>> disk = np.where(np.hypot(cols - 60.3, rows - 58.6) < 40.0, 80.0, 10.0)
    >>> chosen = choose_aperture(disk, "circle")
    >>> chosen.choice, round(chosen.edge.cx, 1), round(chosen.edge.cy, 1), round(chosen.edge.radius, 1)
    ('circle', 60.3, 58.6, 40.0)
    """
    shape = np.shape(signal_map)
    if not isinstance(choice, str):
        mask = np.asarray(choice)
        if mask.shape != shape:
            raise ValueError(f"aperture mask has shape {mask.shape}; expected the map's shape {shape}")
        return ChosenAperture(Aperture.from_mask(mask), "mask", None, None)
    if choice not in APERTURE_CHOICES:
        raise ValueError(f"aperture choice is {choice!r}; expected 'detected', 'circle' or a mask array")
    detected = detect_aperture(signal_map, detection)
    try:
        edge = fit_edge_circle(signal_map, detected, smooth_sigma_px=detection.smooth_sigma_px,
                               margin_px=detection.edge_margin_px)
    except EdgeFitError as error:
        if choice == "circle":
            raise ValueError(f"no circle fits the detected aperture's edge ({error}); use the detected aperture") from None
        logger.info("no edge circle for the detected aperture: %s", error)
        edge = None
    aperture = detected.aperture
    if choice == "detected" and edge is not None:
        aperture = _cut_to_edge(aperture, edge)
    if choice == "circle":
        assert edge is not None
        circle = edge.mask(shape) & ~_holes(detected.aperture.mask)
        aperture = Aperture.from_mask(circle, min_hole_area_px=aperture.min_hole_area_px)
    return ChosenAperture(aperture, choice, edge, detected)


def _cut_to_edge(aperture: Aperture, edge: EdgeCircle) -> Aperture:
    """The aperture less a sliver of halo beyond its edge circle, or as it is (module notes)."""
    inside = edge.mask(aperture.mask.shape)
    outside = int(np.count_nonzero(aperture.mask & ~inside))
    if outside == 0 or outside > EDGE_SLIVER * aperture.valid_count:
        return aperture
    logger.debug("detected aperture cut to its edge circle: %d of %d pixels beyond it", outside, aperture.valid_count)
    return Aperture.from_mask(aperture.mask & inside, min_hole_area_px=aperture.min_hole_area_px)


def _holes(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Background pixels not connected (4-connectivity) to the border: the aperture's holes."""
    framed = cv2.copyMakeBorder(mask.astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    cv2.floodFill(framed, None, (0, 0), 1, flags=4)
    return framed[1:-1, 1:-1] == 0
