"""The random ball test through the station: the reference's error from N seatings of a calibration ball.

A precision ball at the confocal position of a transmission sphere is measured in N random
orientations (Parks, Evans, Shao; NIST): each seating shows another cap of the ball, so the ball's
figure averages towards a constant as ``1 / sqrt(N)`` while the reference's error (transmission
sphere and interferometer) stays. For each seating the calibration asks for it (``seat(k)``: the
operator re-seats the ball, or the simulated mount does), takes ``maps_per_seating`` valid maps
exposed ``settle_s`` later, fits them on one fixed aperture in circle Zernike terms and averages
them robustly; the seatings' means are then averaged robustly themselves (a seating far from the
others, a ball with dirt on it, is rejected and named). The reference's uncertainty is the
covariance of that mean: the seatings' spread, which is the ball's residual plus noise, over N.

Piston, tilt and power are alignment (the ball's position against the focus) and are left out
(zero, with zero covariance); nothing else is unresolved.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.calibrate.measure import (
    CalibrationFailed,
    MapSource,
    alignment_free,
    basis_fitter,
    check_fields,
    position_average,
    stored_reference,
    take_maps,
)
from wavestack.pipeline.averaging import DEFAULT_THRESHOLD, RobustAverage, TooFewMeasurements, robust_average
from wavestack.pipeline.calibration import ReferenceCalibration

__all__ = ["BallCalibration", "BallTestSettings", "calibrate_reference", "ball_reference"]

logger = logging.getLogger(__name__)
_POWER = ((2, 0),)


@dataclass(frozen=True)
class BallTestSettings:
    """How the random ball test runs.

    Attributes
    ----------
    seatings : int
        N (``>= 3``).
    maps_per_seating : int
        Valid maps averaged per seating (``>= 3``).
    settle_s, measure_timeout_s : float
        Maps count only if exposed this long after the seating; longest wait for them, s.
    edge_px : int
        Rim pixels left out of the fixed aperture.
    modes : int
        Noll terms fitted.
    threshold_mad : float
        The robust averaging's rejection threshold (maps of a seating, and seatings).

    Raises
    ------
    ValueError
        A field out of range; the message names it.
    """

    seatings: int = 32
    maps_per_seating: int = 4
    settle_s: float = 0.2
    measure_timeout_s: float = 60.0
    edge_px: int = 2
    modes: int = 36
    threshold_mad: float = DEFAULT_THRESHOLD

    def __post_init__(self) -> None:
        check_fields(self, (("seatings", 3), ("maps_per_seating", 3), ("edge_px", 0), ("modes", 3)), (),
                     ("settle_s", "measure_timeout_s", "threshold_mad"))


@dataclass(frozen=True, eq=False)
class BallCalibration:
    """The answer of a random ball test.

    Attributes
    ----------
    settings : BallTestSettings
    mask : ndarray of bool
        The fixed aperture (its shape is the camera grid).
    pupil : (float, float, float)
        The basis's unit disk, pixels.
    modes : tuple of (n, m)
    seatings : tuple of RobustAverage
        Each seating's robust average of its maps.
    average : RobustAverage
        The robust average of the seatings' means (seatings rejected by index).
    reference, reference_covariance : ndarray, shapes (M,), (M, M)
        The reference's error and its covariance, waves; piston, tilt and power zero.
    """

    settings: BallTestSettings
    mask: NDArray[np.bool_]
    pupil: tuple[float, float, float]
    modes: tuple[tuple[int, int], ...]
    seatings: tuple[RobustAverage, ...]
    average: RobustAverage
    reference: NDArray[np.float64]
    reference_covariance: NDArray[np.float64]


def calibrate_reference(maps: MapSource, seat: Callable[[int], None], settings: BallTestSettings, *,
                        stop: threading.Event | None = None) -> BallCalibration:
    """Run the random ball test (module notes).

    Parameters
    ----------
    maps : MapSource
        The running station's maps.
    seat : callable
        ``seat(k)`` returns once the ball is seated for seating ``k`` (0-based) at a fresh orientation.
    settings : BallTestSettings
    stop : threading.Event, optional
        Set from another thread to abandon the test.

    Raises
    ------
    CalibrationFailed
        The station gives no trusted maps, a map does not cover the aperture, or too many seatings
        are rejected; nothing of the calibration is kept.
    """
    stop = stop or threading.Event()
    fitter = None
    averages: list[RobustAverage] = []
    for index in range(settings.seatings):
        where = f"seating {index + 1} of {settings.seatings}"
        seat(index)
        stack = take_maps(maps, settings.maps_per_seating, settings.settle_s, settings.measure_timeout_s, stop, where)
        if fitter is None:
            fitter = basis_fitter(stack, settings.edge_px, settings.modes)
        averages.append(position_average(fitter, stack, settings.threshold_mad, where))
        logger.info("random ball: %s, %d map(s) kept, rejected %s", where, averages[-1].count,
                    list(averages[-1].rejected))
    assert fitter is not None
    try:
        average = robust_average(np.array([a.coefficients for a in averages]), threshold=settings.threshold_mad)
    except TooFewMeasurements as error:
        raise CalibrationFailed(f"the seatings: {error}") from None
    modes = tuple(fitter.basis.modes)
    keep = alignment_free(modes, _POWER)
    pupil = fitter.basis.pupil
    return BallCalibration(settings=settings, mask=fitter.aperture.mask, pupil=(pupil.cx, pupil.cy, pupil.radius),
                           modes=modes, seatings=tuple(averages), average=average,
                           reference=average.coefficients * keep,
                           reference_covariance=average.coefficient_covariance * np.outer(keep, keep))


def ball_reference(calibration: BallCalibration, wavelength_nm: float, date_utc: str) -> ReferenceCalibration:
    """The stored form of a random ball test's reference."""
    return stored_reference(calibration.mask, calibration.pupil, calibration.modes, calibration.reference,
                            calibration.reference_covariance, method="random-ball",
                            positions=calibration.average.count, unresolved_orders=(), wavelength_nm=wavelength_nm,
                            date_utc=date_utc)
