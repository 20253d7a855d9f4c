"""The N-position rotation calibration through the station: turn the part, measure, derotate in the fitted basis.

The part sits on a rotary mount driven by a PI rotation stage (GCS, one axis in degrees). For each
of N equally spaced positions ``start + k 360 / N`` the calibration moves the stage, waits on target,
waits ``settle_s`` and takes ``maps_per_position`` valid maps in a row from the running station
(:class:`~wavestack.station.LiveMaps`), all exposed after the stage arrived. Each map is fitted on
one fixed aperture (the first position's measured pixels less ``edge_px`` rim pixels) in circle
Zernike polynomials over the measured region's enclosing circle (rim included), whose centre is
taken as the mount's axis;
the maps of a position are averaged robustly in that basis
(:func:`~wavestack.pipeline.averaging.robust_average`: outliers rejected and named, the covariance
of the mean kept), and the positions are separated by
:func:`~wavestack.pipeline.calibration.solve_rotation_test` at the angles read back from the stage.
The stage is returned to the start angle at the end.

Piston and tilt are alignment, not figure (the part is re-seated and re-nulled at every turn): they
are left out of the answer (zero, with zero covariance). What the answer cannot separate, the
rotationally symmetric terms and the angular orders that are multiples of N, is reported as their
sum with the orders named.

A fault ends the calibration and nothing is written: the stage refusing, stalling (not on target
within ``move_timeout_s``) or losing its connection, the station giving no trusted maps, a map that
does not cover the aperture. :class:`CalibrationFailed` says which, at which position.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

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
from wavestack.drivers.errors import DeviceError
from wavestack.pipeline import Fitter
from wavestack.pipeline.averaging import DEFAULT_THRESHOLD, RobustAverage
from wavestack.pipeline.calibration import ReferenceCalibration, RotationSolution, solve_rotation_test

__all__ = ["CalibrationFailed", "PositionRecord", "RotationCalibration", "RotationSettings", "calibrate_rotation",
           "reference_calibration"]

logger = logging.getLogger(__name__)


class RotaryStage(Protocol):
    """What the calibration asks of the rotation stage (a :class:`~wavestack.drivers.pi_gcs.PIHexapod` on one axis)."""

    configured_axes: tuple[str, ...]

    def move_absolute(self, pose: Mapping[str, float]) -> object: ...

    def wait_on_target(self, timeout_s: float) -> dict[str, float]: ...


@dataclass(frozen=True)
class RotationSettings:
    """How the rotation calibration runs.

    Attributes
    ----------
    positions : int
        N, equally spaced over a turn (``>= 2``).
    maps_per_position : int
        Valid maps averaged per position (``>= 3``).
    start_deg : float
        The stage's angle of the first position, degrees.
    settle_s : float
        Maps count only if exposed this long after the stage arrived, s.
    measure_timeout_s, move_timeout_s : float
        Longest wait for a position's maps, and for the stage on target, s.
    edge_px : int
        Rim pixels left out of the fixed aperture.
    modes : int
        Noll terms fitted (every ``(n, m)`` with its ``-m`` partner: 3, 6, 10, 15, 21, 28, 36, ...).
    direction : {1, -1}
        The part's turn, counter-clockwise as displayed, per degree of the stage (-1 for a mount
        seen mirrored or turning the other way).
    threshold_mad : float
        The robust averaging's rejection threshold, scaled MADs.

    Raises
    ------
    ValueError
        A field out of range; the message names it.
    """

    positions: int = 4
    maps_per_position: int = 8
    start_deg: float = 0.0
    settle_s: float = 0.2
    measure_timeout_s: float = 60.0
    move_timeout_s: float = 60.0
    edge_px: int = 2
    modes: int = 36
    direction: int = 1
    threshold_mad: float = DEFAULT_THRESHOLD

    def __post_init__(self) -> None:
        check_fields(self, (("positions", 2), ("maps_per_position", 3), ("edge_px", 0), ("modes", 3)),
                     ("start_deg",), ("settle_s", "measure_timeout_s", "move_timeout_s", "threshold_mad"))
        if self.measure_timeout_s <= 0 or self.move_timeout_s <= 0 or self.threshold_mad <= 0:
            raise ValueError("measure_timeout_s, move_timeout_s and threshold_mad: expected > 0, got "
                             f"{self.measure_timeout_s}, {self.move_timeout_s}, {self.threshold_mad}")
        if self.direction not in (1, -1):
            raise ValueError(f"direction: expected 1 or -1, got {self.direction!r}")

    def targets_deg(self) -> tuple[float, ...]:
        """The stage's N target angles, degrees."""
        return tuple(self.start_deg + k * 360.0 / self.positions for k in range(self.positions))


@dataclass(frozen=True, eq=False)
class PositionRecord:
    """One position of the calibration: where the stage went and what the maps gave.

    Attributes
    ----------
    index : int
    target_deg, angle_deg : float
        The stage's target and the angle read back on arrival, degrees.
    average : RobustAverage
        The robust average of the position's maps (kept and rejected maps by index).
    """

    index: int
    target_deg: float
    angle_deg: float
    average: RobustAverage


@dataclass(frozen=True, eq=False)
class RotationCalibration:
    """The answer of a rotation calibration.

    Attributes
    ----------
    settings : RotationSettings
    mask : ndarray of bool, shape (H, W)
        The fixed aperture the maps were fitted on (the camera grid is its shape).
    pupil : (float, float, float)
        The basis's unit disk ``(cx, cy, radius)``, pixels (its centre is the mount's axis).
    modes : tuple of (n, m)
        The Noll terms of every coefficient vector.
    solution : RotationSolution
        Part, reference and the unresolved sums, waves of wavefront, with their covariances;
        piston and tilt are zero (module notes).
    records : tuple of PositionRecord
    reference_map, part_map : ndarray, shape (H, W)
        The reference's and the part's separated figure on ``mask``, waves (NaN outside).
    reference_stderr_map : ndarray, shape (H, W)
        The standard error of ``reference_map`` per pixel, waves (from the coefficients' covariance).
    """

    settings: RotationSettings
    mask: NDArray[np.bool_]
    pupil: tuple[float, float, float]
    modes: tuple[tuple[int, int], ...]
    solution: RotationSolution
    records: tuple[PositionRecord, ...]
    reference_map: NDArray[np.float64]
    part_map: NDArray[np.float64]
    reference_stderr_map: NDArray[np.float64]


def calibrate_rotation(maps: MapSource, stage: RotaryStage, settings: RotationSettings, *,
                       on_arrival: Callable[[], None] | None = None,
                       stop: threading.Event | None = None) -> RotationCalibration:
    """Run the N-position calibration (module notes).

    Parameters
    ----------
    maps : MapSource
        The running station's maps.
    stage : RotaryStage
        The rotation stage, opened, its first configured axis turning the part.
    settings : RotationSettings
    on_arrival : callable, optional
        Called once the stage is on target, before the maps are taken (the simulated mount turns
        the simulated part there).
    stop : threading.Event, optional
        Set from another thread to abandon the calibration.

    Returns
    -------
    RotationCalibration

    Raises
    ------
    CalibrationFailed
        Any fault (module notes); nothing of the calibration is kept.
    """
    stop = stop or threading.Event()
    axis = stage.configured_axes[0]
    records: list[PositionRecord] = []
    fitter = None
    for index, target in enumerate(settings.targets_deg()):
        where = f"position {index + 1} of {settings.positions} ({target:g} deg)"
        angle = _turn(stage, axis, target, settings.move_timeout_s, where)
        if on_arrival is not None:
            on_arrival()
        stack = take_maps(maps, settings.maps_per_position, settings.settle_s, settings.measure_timeout_s, stop, where)
        if fitter is None:
            fitter = basis_fitter(stack, settings.edge_px, settings.modes)
        average = position_average(fitter, stack, settings.threshold_mad, where)
        records.append(PositionRecord(index, target, angle, average))
        logger.info("rotation calibration: %s at %.4f deg, %d map(s) kept, rejected %s", where, angle,
                    average.count, list(average.rejected))
    _turn(stage, axis, settings.start_deg, settings.move_timeout_s, "the return to the start angle")
    assert fitter is not None
    return _answer(fitter, settings, tuple(records))


def _turn(stage: RotaryStage, axis: str, target: float, timeout_s: float, where: str) -> float:
    try:
        stage.move_absolute({axis: target})
        return float(stage.wait_on_target(timeout_s)[axis])
    except DeviceError as error:
        raise CalibrationFailed(f"{where}: the rotation stage: {error}") from None


def _answer(fitter: Fitter, settings: RotationSettings, records: Sequence[PositionRecord]) -> RotationCalibration:
    modes = tuple(fitter.basis.modes)
    angles = np.deg2rad([settings.direction * (r.angle_deg - settings.start_deg) for r in records])
    solution = solve_rotation_test(modes, np.array([r.average.coefficients for r in records]), angles,
                                   np.array([r.average.coefficient_covariance for r in records]))
    solution = _without(solution, alignment_free(modes, ()))  # piston and tilt (module notes)
    mask = fitter.aperture.mask
    reference_map = np.where(mask, fitter.surface(solution.reference), np.nan)
    part_map = np.where(mask, fitter.surface(solution.part), np.nan)
    basis = np.stack([fitter.surface(np.eye(len(modes))[j]) for j in range(len(modes))], axis=-1)[mask]
    variance = np.einsum("pi,ij,pj->p", basis, solution.reference_covariance, basis)
    stderr = np.full(mask.shape, np.nan)
    stderr[mask] = np.sqrt(np.clip(variance, 0.0, None))
    pupil = fitter.basis.pupil
    return RotationCalibration(settings=settings, mask=mask, pupil=(pupil.cx, pupil.cy, pupil.radius), modes=modes,
                               solution=solution, records=tuple(records), reference_map=reference_map,
                               part_map=part_map, reference_stderr_map=stderr)


def _without(solution: RotationSolution, keep: NDArray[np.float64]) -> RotationSolution:
    """``solution`` with the terms where ``keep`` is 0 set to zero (values and covariances)."""
    outer = np.outer(keep, keep)
    return RotationSolution(
        modes=solution.modes, positions=solution.positions, angles_rad=solution.angles_rad,
        part=solution.part * keep, reference=solution.reference * keep, unresolved=solution.unresolved * keep,
        resolved=solution.resolved & (keep > 0), unresolved_orders=solution.unresolved_orders,
        part_covariance=solution.part_covariance * outer, reference_covariance=solution.reference_covariance * outer,
    )


def reference_calibration(calibration: RotationCalibration, wavelength_nm: float,
                          date_utc: str) -> ReferenceCalibration:
    """The stored form of a rotation calibration's reference (:func:`~wavestack.calibrate.measure.stored_reference`)."""
    solution = calibration.solution
    return stored_reference(calibration.mask, calibration.pupil, calibration.modes, solution.reference,
                            solution.reference_covariance, method="rotation", positions=solution.positions,
                            unresolved_orders=solution.unresolved_orders, wavelength_nm=wavelength_nm,
                            date_utc=date_utc)
