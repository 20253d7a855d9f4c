"""The obscuration ratio of the ``annulus`` fit method: given, or measured from the aperture's hole.

The ``annulus`` method fits Mahajan's annular Zernike polynomials
(:func:`~wavestack.pipeline.zernike.annular_zernike_basis`) over the annulus
``eps <= rho <= 1`` of the pupil circle, directly on the pixel grid. The pupil is found as for
``circle`` (the minimum enclosing circle through the outermost valid pixel centres, or the
user's). The inner radius, when not given, is measured the same way from the inside: the largest
circle concentric with the pupil that holds no valid pixel centre (the distance from the pupil
centre to the nearest valid pixel centre), so that every fitted pixel centre lies in
``eps <= rho <= 1`` exactly as every one lies in ``rho <= 1``.

This inscribed circle was chosen over a circle fitted to the hole's edge because it needs the
pupil's centre (the annular terms are concentric by definition: a fitted hole circle off that
centre would not define their ``eps`` anyway), it is exact for a pixelated round hole up to the
pixel grid, and it never places a fitted pixel inside the inner circle. For a hole that is not
round or not centred, it is set by the hole's nearest edge; such apertures are better fitted by
``csf-qcm``, which maps them onto a concentric annulus.

References
----------
V. N. Mahajan, "Zernike annular polynomials for imaging systems with annular pupils",
J. Opt. Soc. Am. 71, 75-85 (1981).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from .._checks import is_real
from ..aperture import Aperture
from .fitter import Fitter
from .results import Pupil

# A pixel of margin beyond the hole's bounding box holds its nearest valid pixels (the hole's
# polygon runs half a pixel into the hole from their centres).
_HOLE_MARGIN_PX = 2


@dataclass(frozen=True)
class Obscuration:
    """The obscuration ratio of an annular basis and where it came from.

    Attributes
    ----------
    ratio : float
        ``eps``, inner over outer radius, in (0, 1).
    source : {"given", "measured"}
        ``given`` by the caller, or ``measured``: the largest circle concentric with the pupil
        free of valid pixel centres, over the pupil radius.
    """

    ratio: float
    source: str


def check_obscuration(value: object, name: str = "obscuration") -> float:
    """A given obscuration ratio as a float in (0, 1).

    Raises
    ------
    ValueError
        Naming ``name`` and the range expected.
    """
    if not is_real(value) or not (math.isfinite(float(value)) and 0.0 < float(value) < 1.0):  # type: ignore[arg-type]
        raise ValueError(f"{name}: expected a number between 0 and 1 (inner over outer radius), got {value!r}")
    return float(value)  # type: ignore[arg-type]


def annulus_obscuration(
    aperture: Aperture, pupil: Pupil, given: float | None = None, fit_mask: NDArray[np.bool_] | None = None
) -> Obscuration:
    """The obscuration ratio of the ``annulus`` method on an aperture.

    Parameters
    ----------
    aperture : Aperture
    pupil : Pupil
        The outer circle, pixels (cx a column, cy a row).
    given : float, optional
        The ratio, 0 < given < 1; when given, the aperture is not measured.
    fit_mask : ndarray of bool, shape (rows, cols), optional
        The fitted pixels, when not the aperture's; the inner circle holds none of them either.

    Returns
    -------
    Obscuration

    Raises
    ------
    ValueError
        For a given ratio outside (0, 1); for an aperture without a hole around the pupil
        centre (the message says to give the obscuration, or to use ``csf-qcm``).

    Examples
    --------
    A ring of radii 12 and 30 px around the centre of a 64 x 64 frame (its nearest pixel centres
    lie 12.03 px from the centre):

    >>> import numpy as np
    >>> rows, cols = np.mgrid[:64, :64]
    >>> r = np.hypot(rows - 31.5, cols - 31.5)
    >>> aperture = Aperture.from_mask((r <= 30) & (r >= 12))
    >>> found = annulus_obscuration(aperture, Pupil(31.5, 31.5, 30.0))
    >>> found.source, round(found.ratio, 3)
    ('measured', 0.401)
    """
    if given is not None:
        return Obscuration(check_obscuration(given), "given")
    hole = _central_hole(aperture, pupil)
    if hole is None:
        raise ValueError(f"obscuration: the aperture ({aperture.describe()}) has no hole around the pupil centre "
                         f"(col {pupil.cx:.2f}, row {pupil.cy:.2f}) to measure; expected --obscuration E "
                         "(0 < E < 1), or method 'csf-qcm' for an off-centre hole")
    mask = aperture.mask if fit_mask is None else aperture.mask | fit_mask
    inner = _nearest_valid_distance(mask, pupil, hole)
    ratio = inner / pupil.radius
    if not 0.0 < ratio < 1.0:
        raise ValueError(f"obscuration: the hole around the pupil centre gives an inner radius of {inner:.3g} px "
                         f"for a pupil of {pupil.radius:.3g} px; expected a ratio between 0 and 1 "
                         "(give --obscuration E)")
    return Obscuration(ratio, "measured")


def _central_hole(aperture: Aperture, pupil: Pupil) -> NDArray[np.float64] | None:
    """The hole polygon (physical x = col, y = -row) that holds the pupil centre, if any."""
    centre = (float(pupil.cx), -float(pupil.cy))
    for polygon in aperture.holes:
        if cv2.pointPolygonTest(polygon.astype(np.float32).reshape(-1, 1, 2), centre, False) > 0:
            return polygon
    return None


def _nearest_valid_distance(mask: NDArray[np.bool_], pupil: Pupil, hole: NDArray[np.float64]) -> float:
    """Distance (px) from the pupil centre to the nearest pixel centre of ``mask``.

    Searched in the hole's bounding box widened by a margin; a distance beyond that box's edge
    could hide a nearer pixel outside it, so then the whole mask is searched.
    """
    rows, cols = mask.shape
    row0 = max(int(np.floor(-hole[:, 1].max())) - _HOLE_MARGIN_PX, 0)
    row1 = min(int(np.ceil(-hole[:, 1].min())) + _HOLE_MARGIN_PX + 1, rows)
    col0 = max(int(np.floor(hole[:, 0].min())) - _HOLE_MARGIN_PX, 0)
    col1 = min(int(np.ceil(hole[:, 0].max())) + _HOLE_MARGIN_PX + 1, cols)
    nearest = _nearest_in(mask, pupil, row0, row1, col0, col1)
    reach = min(pupil.cy - row0 if row0 > 0 else math.inf, row1 - 1 - pupil.cy if row1 < rows else math.inf,
                pupil.cx - col0 if col0 > 0 else math.inf, col1 - 1 - pupil.cx if col1 < cols else math.inf)
    if nearest <= reach:
        return nearest
    return _nearest_in(mask, pupil, 0, rows, 0, cols)


def _nearest_in(mask: NDArray[np.bool_], pupil: Pupil, row0: int, row1: int, col0: int, col1: int) -> float:
    found_rows, found_cols = np.nonzero(mask[row0:row1, col0:col1])
    if found_rows.size == 0:
        return math.inf
    return float(np.min(np.hypot(found_rows + row0 - pupil.cy, found_cols + col0 - pupil.cx)))


def with_obscuration_source(fitter: Fitter, annular: Obscuration | None) -> Fitter:
    """The fitter, with where its obscuration ratio came from in ``diagnostics.obscuration_source``."""
    if annular is not None:
        fitter.diagnostics = dataclasses.replace(fitter.diagnostics, obscuration_source=annular.source)
    return fitter
