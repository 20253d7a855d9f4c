"""The two levels of a modulation map, the disk's and the halo's, and the half-way threshold between them.

A measured optic shows up in a modulation (or fringe-contrast) map as a plateau, the *disk*, surrounded by
a dimmer, often speckled *halo* (stray light, diffraction from the rim, the edge of the beam). Where the
optic ends the modulation falls from the disk's level to the halo's over the width of the imaging
system's edge response; the edge is where it is half way [1]_, the 50 % point of the edge spread
function.

Why the half-way point, and why these estimators (numerical reasoning):

* Both levels are **medians** of pixel sets chosen from a coarse mask: the disk level over the coarse
  mask eroded by ``margin_px`` (so the edge response itself is left out), the halo level over a band
  ``margin_px`` to ``margin_px + band_px`` outside it. A median has a 50 % breakdown point: dust
  dropouts in the disk, or a bright piece of halo along part of the rim, move it by at most the
  spread of the majority population, unlike a mean or Otsu's between-class criterion (which moves
  with the *areas* of the two classes, hence with the field of view).
* A blurred step keeps its 50 % crossing where the step is, for any blur symmetric about the edge
  (a straight edge exactly; a curved edge of radius ``R`` moves by about ``sigma**2 / (2 R)`` for a
  Gaussian of ``sigma``). So the half-way threshold locates the edge independently of the edge
  response width, where any other fraction would move it by a fraction of that width.
* For the same reason, smoothing the map with a Gaussian of ``sigma`` ~ the speckle grain before
  thresholding does not move the edge, but it averages each speckle towards its neighbourhood: a
  bright grain of halo touching the rim falls below the half-way level instead of being welded to
  the disk by the morphological closing. See :func:`smoothed`.
* The halo is not one level: where it touches the rim on one side it is brighter there, and the
  half-way point *there* is half way to that local level (a blurred step from 80 to 38 crosses
  the global midpoint 44 at 0.84 sigma outside its edge, and the halo's speckle peaks cross it
  outright). So the threshold is a map, half way between the disk level and a local halo level,
  see :func:`local_threshold`.

References
----------
.. [1] ISO 12233:2017, *Photography - Electronic still picture imaging - Resolution and spatial
   frequency responses*: the edge spread function and its 50 % point.
.. [2] P. J. Huber and E. M. Ronchetti, *Robust Statistics*, 2nd ed., Wiley (2009), sec. 1.4
   (breakdown point of the median).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["ModulationLevels", "local_threshold", "modulation_levels", "smoothed"]

MARGIN_PX = 3  # distance from the coarse edge to the pixels each level is taken from, pixels
BAND_PX = 12  # width of the halo band outside the coarse edge, pixels
_BLEND = 0.05  # weight of the global halo level in the local one (the band's weight is up to 1)


@dataclass(frozen=True)
class ModulationLevels:
    """Disk and halo levels of a modulation map, in map units.

    Attributes
    ----------
    disk : float
        Median over the coarse aperture less the pixels within ``margin_px`` (default 3) of
        its edge.
    halo : float
        Median over the band ``margin_px`` to ``margin_px + 12`` px outside the coarse aperture; where that band is empty (the
        aperture fills the frame), the median of everything outside the coarse aperture, else the
        map's minimum.
    """

    disk: float
    halo: float

    @property
    def midpoint(self) -> float:
        """Half way between the two levels: the edge threshold, map units."""
        return 0.5 * (self.disk + self.halo)


def modulation_levels(
    values: NDArray[np.floating], coarse: NDArray[np.uint8], margin_px: float = MARGIN_PX
) -> ModulationLevels:
    """Robust disk and halo levels of a map around a coarse aperture mask.

    Parameters
    ----------
    values : NDArray, shape (rows, cols)
        Modulation map (NaN = no data, ignored).
    coarse : NDArray[np.uint8], shape (rows, cols)
        Coarse aperture (1 = inside), e.g. an Otsu threshold cleaned by morphology.
    margin_px : float, optional
        Distance from the coarse edge to the pixels each level is taken from, pixels (default
        3): at least the half-width of the map's edge response, so neither level takes in the
        edge itself (a local-contrast map's response is as wide as its box).

    Returns
    -------
    ModulationLevels
        Medians of the finite values inside and outside, see the class. A coarse aperture thinner
        than ``2 MARGIN_PX`` (nothing left after the erosion) gives the median over the whole of it.
    """
    finite = np.isfinite(values)
    inside = (_distance(coarse) > margin_px) & finite
    if not inside.any():
        inside = coarse.view(np.bool_) & finite
    outside = _band(values, coarse, margin_px)
    if not outside.any():
        outside = ~coarse.view(np.bool_) & finite
    disk = float(np.median(values[inside]))
    halo = float(np.median(values[outside])) if outside.any() else float(np.min(values[finite]))
    return ModulationLevels(disk, halo)


def _distance(mask: NDArray[np.uint8]) -> NDArray[np.float32]:
    """Euclidean distance (OpenCV's 5 x 5 mask approximation) of each set pixel to the nearest unset one."""
    return cv2.distanceTransform(mask, cv2.DIST_L2, 5)


def _band(values: NDArray, coarse: NDArray[np.uint8], margin_px: float) -> NDArray[np.bool_]:
    """Pixels ``margin_px`` to ``margin_px + BAND_PX`` outside the coarse aperture, with data."""
    outside = _distance(np.ascontiguousarray(1 - coarse))
    return (outside > margin_px) & (outside <= margin_px + BAND_PX) & np.isfinite(values)


def local_threshold(
    values: NDArray, coarse: NDArray[np.uint8], levels: ModulationLevels, margin_px: float = MARGIN_PX
) -> NDArray[np.float32]:
    """Half way between the disk level and the local halo level, at every pixel.

    The local halo level is the band's values (``margin_px`` to ``margin_px + 12`` px outside the coarse aperture) averaged
    by a Gaussian of ``BAND_PX`` (12 px, computed at quarter resolution) with normalised convolution, blended with weight 0.05
    towards the global halo level where the band is far away:
    ``h = (G * (v b) + 0.05 H) / (G * b + 0.05)``, clipped to at most the disk level.

    Parameters
    ----------
    values : NDArray, shape (rows, cols)
        The map (NaN = no data).
    coarse : NDArray[np.uint8], shape (rows, cols)
        Coarse aperture the band is taken around.
    levels : ModulationLevels
        The global disk and halo levels.
    margin_px : float, optional
        As for :func:`modulation_levels`.

    Returns
    -------
    NDArray[np.float32], shape (rows, cols)
        The threshold map, map units.
    """
    band = _band(values, coarse, margin_px)
    num = _wide_blur(np.where(band, values, 0.0).astype(np.float32))
    den = _wide_blur(band.astype(np.float32))
    halo = (num + _BLEND * levels.halo) / (den + _BLEND)
    np.minimum(halo, levels.disk, out=halo)
    return (0.5 * (levels.disk + halo)).astype(np.float32)


def _wide_blur(image: NDArray[np.float32]) -> NDArray[np.float32]:
    """Gaussian of ``BAND_PX`` computed at a quarter of the resolution (the field is smooth on
    that scale; area averaging down, bilinear back up), ~16 times cheaper than at full size."""
    rows, cols = image.shape
    small = cv2.resize(image, (max(1, cols // 4), max(1, rows // 4)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), BAND_PX / 4.0, borderType=cv2.BORDER_REPLICATE)
    return cv2.resize(small, (cols, rows), interpolation=cv2.INTER_LINEAR)


def smoothed(values: NDArray, sigma_px: float) -> NDArray[np.float32]:
    """Gaussian smoothing that ignores NaN (normalised convolution); NaN pixels stay NaN.

    Parameters
    ----------
    values : NDArray, shape (rows, cols)
        Real map, NaN where there is no data.
    sigma_px : float
        Standard deviation of the Gaussian, pixels; 0 returns a float32 copy.

    Returns
    -------
    NDArray[np.float32], shape (rows, cols)
        ``G * (v w) / G * w`` with ``w`` = 1 on finite pixels, 0 on NaN [1]_.

    References
    ----------
    .. [1] H. Knutsson and C.-F. Westin, "Normalized and differential convolution", Proc. IEEE
       CVPR, 515-523 (1993).
    """
    data = np.asarray(values, dtype=np.float32)
    if sigma_px <= 0:
        return data.copy()
    nan = np.isnan(data)
    if not nan.any():
        return cv2.GaussianBlur(data, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    weight = (~nan).astype(np.float32)
    blurred = cv2.GaussianBlur(np.where(nan, 0.0, data).astype(np.float32), (0, 0), sigma_px,
                               borderType=cv2.BORDER_REFLECT)
    norm = cv2.GaussianBlur(weight, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = blurred / norm
    out[nan] = np.nan
    return out
