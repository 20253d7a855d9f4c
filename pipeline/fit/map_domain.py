"""The domain a mapped method maps onto the unit disk (or annulus): the aperture where the fitted pixels are.

A mapped basis (``csf-qcm``, ``conformal``) is orthogonal over the image of its domain, and a fit
is well conditioned only where the samples cover that image. The pixels fitted may be fewer than
the aperture's: a measured map's own valid pixels (:func:`~wavestack.pipeline.fit.build_fitter`'s
``fit_mask``) inside an outline that was detected from them. Detection opens and closes the mask,
so along a ragged edge (the pixel staircase of a slanted or rounded strip, a rim that lost a few
pixels) the outline bridges the notches and reaches past the outermost measured pixels. Mapped
with the rest, that band holds no sample; its image is a band along the rim of the unit disk
where the high-order modes peak, and they lose their support. On the real 259 x 33 Zygo strip
(``monolithic_zygo_test.datx``) the band is 516 pixels, 6 % of the outline, and it takes the Gram
matrix's condition number from 9.1 (the map built on the measured pixels) to 122.

The choice, made once here for every caller: the map's domain is the aperture trimmed to the
fitted pixels, namely the fitted pixels with their holes filled except those around one of the
aperture's own holes (its obscurations, the holes of at least ``min_hole_area_px`` pixels), inside
the aperture's outer outline, its largest 8-connected component.

* Drop-outs inside the fitted region stay in the domain: the surface is there, only unmeasured,
  the map stays continuous across them and each costs the Gram matrix just its own samples.
  Cutting them out instead would turn every drop-out into a hole of the domain, which no map onto
  a disk or an annulus can take.
* The outline then traces the outermost fitted pixels, and an obscuration's edge the innermost
  ones, so the samples reach every rim of the unit disk or annulus; the coefficients describe the
  surface that was measured, not an extrapolation over a band.
* A domain no map can take (several holes left where the aperture has them) falls back to the
  aperture itself, as before the trim.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.ndimage
from numpy.typing import NDArray

from ..aperture import Aperture, Topology

logger = logging.getLogger(__name__)

_EIGHT = np.ones((3, 3), dtype=bool)  # 8-connected foreground, the aperture's own convention


def map_domain(aperture: Aperture, fit_mask: NDArray[np.bool_] | None) -> Aperture:
    """The region a mapped method maps: the aperture trimmed to the fitted pixels (module notes).

    Parameters
    ----------
    aperture : Aperture
        The aperture (its outline and obscurations).
    fit_mask : ndarray of bool, shape ``aperture.shape``, or None
        The pixels fitted; None: the aperture's own (the aperture is returned).

    Returns
    -------
    Aperture
        The domain, with the aperture's ``min_hole_area_px``; ``aperture`` itself when the trim
        changes nothing or leaves a domain that neither a disk nor an annulus map can take.

    Examples
    --------
    A 9 x 41 strip whose outline reaches one column past its measured pixels on the left, with a
    drop-out inside: the domain is the measured strip, the drop-out filled.

    >>> import numpy as np
    >>> outline = np.zeros((11, 44), dtype=bool)
    >>> outline[1:10, 1:42] = True
    >>> measured = outline.copy()
    >>> measured[:, 1] = False
    >>> measured[5, 20] = False
    >>> domain = map_domain(Aperture.from_mask(outline), measured)
    >>> int(domain.valid_count), int(outline.sum()), bool(domain.mask[5, 20]), bool(domain.mask[5, 1])
    (360, 369, True, False)
    """
    if fit_mask is None:
        return aperture
    outline = aperture.mask
    filled_outline = scipy.ndimage.binary_fill_holes(outline)
    obscurations = _large_holes(outline, filled_outline, aperture.min_hole_area_px)
    filled = scipy.ndimage.binary_fill_holes(fit_mask)
    gaps, count = scipy.ndimage.label(filled & ~fit_mask)  # the fitted pixels' holes, 4-connected
    kept = np.zeros(count + 1, dtype=bool)
    kept[np.unique(gaps[obscurations])] = True  # a hole of the fitted pixels around an obscuration stays
    kept[0] = False
    domain = filled & filled_outline & ~kept[gaps]
    components, count = scipy.ndimage.label(domain, structure=_EIGHT)
    if count == 0:
        return aperture
    if count > 1:
        domain = components == 1 + int(np.argmax(np.bincount(components.ravel())[1:]))
    if np.array_equal(domain, outline):
        return aperture
    trimmed = Aperture.from_mask(domain, min_hole_area_px=aperture.min_hole_area_px)
    if trimmed.topology is Topology.UNSUPPORTED:
        logger.info("the fitted pixels leave %s; the map keeps the aperture's outline", trimmed.describe())
        return aperture
    logger.debug("map domain: %d of the outline's %d pixels (the outline trimmed to the fitted pixels)",
                 trimmed.valid_count, aperture.valid_count)
    return trimmed


def _large_holes(mask: NDArray[np.bool_], filled: NDArray[np.bool_], min_area_px: float) -> NDArray[np.bool_]:
    """Pixels of the holes of ``mask`` (``filled`` its holes filled) of at least ``min_area_px`` pixels."""
    holes, count = scipy.ndimage.label(filled & ~mask)  # 4-connected, as the aperture counts them
    sizes = np.bincount(holes.ravel(), minlength=count + 1)
    large = sizes >= min_area_px
    large[0] = False
    return large[holes]
