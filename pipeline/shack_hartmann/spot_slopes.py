"""Spot displacements to wavefront slopes, and slopes in other units.

A spot moves by ``f * grad W`` when the wavefront ``W`` tilts over its lenslet (``f`` the
lenslet focal length; Southwell, J. Opt. Soc. Am. 70, 998-1006, 1980).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float
from .centroids import SpotMeasurement


@dataclass(frozen=True, eq=False)
class SlopeResult:
    """Wavefront slopes per lenslet (in the order of the lattice's sites).

    Attributes
    ----------
    slopes_x, slopes_y : ndarray, shape (L,)
        ``dW/dx`` and ``dW/dy`` in radians (W and x in the same length unit), x right and
        y up; NaN where not valid.
    valid : ndarray of bool, shape (L,)
        Lenslets valid in both the measurement and the reference.
    """

    slopes_x: NDArray[np.float64]
    slopes_y: NDArray[np.float64]
    valid: NDArray[np.bool_]


def slopes(
    measurement: SpotMeasurement,
    reference: SpotMeasurement | ArrayLike,
    focal_length_um: float,
    pixel_um: float,
) -> SlopeResult:
    """Wavefront slopes from spot displacements.

    ``slope = displacement * pixel_um / focal_length_um`` (small angles, radians). Sign
    convention: the wavefront ``W`` is the one whose gradient the spots follow, spot
    displacement ``= +f * grad W`` with x right and y up. A column displacement ``dc`` gives
    ``dW/dx = dc * pixel / f``; a row displacement ``dr`` gives ``dW/dy = -dr * pixel / f``
    (rows grow downward). The slopes are dimensionless: ``dW/dx`` with ``W`` and ``x`` in the
    same unit, e.g. micrometres of wavefront per micrometre in the lenslet plane; the lenslet
    plane coordinate of a camera pixel is ``pixel_um`` times its pixel coordinate when the
    lenslet array sits on the camera (see :func:`convert_slopes` for other units).

    Parameters
    ----------
    measurement : SpotMeasurement
        Spots of the aberrated frame, L lenslets.
    reference : SpotMeasurement or array_like of shape (L, 2)
        Reference spot positions ``(col, row)`` in pixels: a measurement of a flat wavefront,
        or e.g. ``lattice.centres()`` (the ideal reference).
    focal_length_um : float
        Lenslet focal length, micrometres, ``> 0``.
    pixel_um : float
        Camera pixel pitch, micrometres, ``> 0``.

    Returns
    -------
    SlopeResult

    Raises
    ------
    ValueError
        If ``measurement`` is not a SpotMeasurement, the reference has another number of
        lenslets, or a length is not a positive finite number.

    References
    ----------
    Southwell (1980), J. Opt. Soc. Am. 70, 998 (slope = displacement / focal length).
    """
    if not isinstance(measurement, SpotMeasurement):
        raise ValueError(f"measurement must be a SpotMeasurement, got {type(measurement).__name__}")
    focal = positive_float(focal_length_um, "focal_length_um")
    pixel = positive_float(pixel_um, "pixel_um")
    count = measurement.centroids.shape[0]
    if isinstance(reference, SpotMeasurement):
        ref_positions, ref_valid = reference.centroids, reference.valid
    else:
        ref_positions = np.asarray(reference, dtype=np.float64)
        ref_valid = np.isfinite(ref_positions).all(axis=1) if ref_positions.ndim == 2 else None
    if ref_positions.shape != (count, 2):
        raise ValueError(
            f"reference must hold {count} positions (L, 2) like the measurement, got shape {np.shape(ref_positions)}"
        )
    valid = measurement.valid & ref_valid
    displacement = measurement.centroids - ref_positions
    scale = pixel / focal
    slope_x = np.where(valid, displacement[:, 0] * scale, np.nan)
    slope_y = np.where(valid, -displacement[:, 1] * scale, np.nan)
    return SlopeResult(slopes_x=slope_x, slopes_y=slope_y, valid=valid)


def convert_slopes(
    result: SlopeResult, *, wavefront_unit_um: float, length_unit_um: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Express slopes as wavefront units per length unit.

    ``slope' = slope_rad * length_unit_um / wavefront_unit_um``. Examples: micrometres of
    wavefront per camera pixel (``wavefront_unit_um=1, length_unit_um=pixel_um``), the unit
    the reconstructors want for lenslet centres given in pixels; waves per pupil radius
    (``wavefront_unit_um=wavelength_um, length_unit_um=pupil_radius_um``).

    Parameters
    ----------
    result : SlopeResult
        Slopes in radians.
    wavefront_unit_um : float
        Size of the wavefront unit in micrometres (1 for micrometres, the wavelength for
        waves), ``> 0``.
    length_unit_um : float
        Size of the length unit in micrometres (pixel pitch, pupil radius, ...), ``> 0``.

    Returns
    -------
    slopes_x, slopes_y : ndarray, shape (L,)

    Raises
    ------
    ValueError
        If a unit is not a positive finite number or ``result`` is not a SlopeResult.
    """
    if not isinstance(result, SlopeResult):
        raise ValueError(f"result must be a SlopeResult, got {type(result).__name__}")
    factor = positive_float(length_unit_um, "length_unit_um") / positive_float(
        wavefront_unit_um, "wavefront_unit_um"
    )
    return result.slopes_x * factor, result.slopes_y * factor
