"""What every calibration shares: maps from the running station, the fixed aperture and basis, the robust
average of one position's (or seating's) maps, and the stored form of the reference it found.

A calibration takes ``count`` valid maps in a row exposed ``settle_s`` after its move (the stage on
target, the ball re-seated) from the station (:class:`~wavestack.station.LiveMaps`); fits them in
circle Zernike polynomials on one fixed aperture, the first measurement's measured pixels less
``edge_px`` rim pixels, over the circle of the whole measured region (rim included, so the stored
disk covers every pixel a later measurement's aperture holds); and averages them robustly
(:func:`~wavestack.pipeline.averaging.robust_average`: outliers rejected and named, the covariance of
the mean kept). Any failure is a :class:`CalibrationFailed` naming where and why.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from wavestack.pipeline import Aperture, Fitter, build_fitter, zernike_basis
from wavestack.pipeline.averaging import RobustAverage, TooFewMeasurements, robust_average
from wavestack.pipeline.calibration import ReferenceCalibration
from wavestack.station.live_maps import MapSample, UntrustedMeasurement

__all__ = ["CalibrationFailed", "MapSource", "alignment_free", "basis_fitter", "check_fields", "position_average",
           "stored_reference", "take_maps"]

MIN_COVERED = 0.95  # of the fixed aperture a map must measure


class CalibrationFailed(RuntimeError):
    """The calibration stopped before its answer; the message names the position and the reason."""


class MapSource(Protocol):
    """The station's maps (:class:`~wavestack.station.LiveMaps`)."""

    def collect(self, count: int, *, max_results: int, not_before_ns: int, timeout_s: float,
                stop: threading.Event) -> list[MapSample]: ...


def check_fields(settings: object, integers: Sequence[tuple[str, int]], finite: Sequence[str],
                 nonnegative: Sequence[str]) -> None:
    """A settings value's checks: integers at least their bound, finite numbers, and those of them ``>= 0``.

    Raises
    ------
    ValueError
        Naming the first field out of range.
    """
    for name, low in integers:
        value = getattr(settings, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")
    for name in (*finite, *nonnegative):
        value = getattr(settings, name)
        if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise ValueError(f"{name}: expected a finite number, got {value!r}")
        if name in nonnegative and value < 0:
            raise ValueError(f"{name}: expected a number >= 0, got {value!r}")


def take_maps(maps: MapSource, count: int, settle_s: float, timeout_s: float, stop: threading.Event,
              where: str) -> NDArray[np.float64]:
    """``count`` valid maps in a row exposed ``settle_s`` after now, stacked (K, H, W), waves."""
    after = time.time_ns() + int(round(settle_s * 1e9))
    try:
        samples = maps.collect(count, max_results=4 * count, not_before_ns=after, timeout_s=timeout_s + settle_s,
                               stop=stop)
    except UntrustedMeasurement as error:
        raise CalibrationFailed(f"{where}: no trusted maps: {error}") from None
    return np.stack([np.asarray(sample.waves, dtype=np.float64) for sample in samples])


def basis_fitter(stack: NDArray[np.float64], edge_px: int, modes: int) -> Fitter:
    """The circle fitter on the fixed aperture of the first measurement (module notes)."""
    measured = np.all(np.isfinite(stack), axis=0)
    labels, count = ndimage.label(measured)
    if count == 0:
        raise CalibrationFailed("position 1: the maps measure no pixel")
    sizes = ndimage.sum_labels(measured, labels, index=np.arange(1, count + 1))
    region = labels == 1 + int(np.argmax(sizes))
    pupil = Aperture.from_mask(region).enclosing_circle()
    mask = region
    if edge_px > 0:
        mask = ndimage.binary_erosion(region, structure=np.ones((3, 3), bool), iterations=edge_px)
    if not mask.any():
        raise CalibrationFailed("position 1: the maps leave no aperture to fit after the rim is taken off")
    return build_fitter(mask, "circle", modes, pupil=pupil, dtype=np.float64)


def position_average(fitter: Fitter, stack: NDArray[np.float64], threshold: float, where: str) -> RobustAverage:
    """The robust average of one position's maps in the fitter's basis, with the maps on its aperture."""
    mask = fitter.aperture.mask
    covered = np.isfinite(stack[:, mask]).mean(axis=1)
    if covered.min() < MIN_COVERED:
        raise CalibrationFailed(f"{where}: a map covers {100 * covered.min():.1f} % of the fixed aperture; "
                                f"expected >= {100 * MIN_COVERED:.0f} % (the part or the aperture moved?)")
    coefficients = np.array([fitter.fit(np.where(mask, frame, np.nan), nan_policy="omit").coefficients
                             for frame in stack])
    try:
        return robust_average(coefficients, np.where(mask, stack, np.nan), threshold=threshold)
    except TooFewMeasurements as error:
        raise CalibrationFailed(f"{where}: {error}") from None


def alignment_free(modes: Sequence[tuple[int, int]], alignment: Sequence[tuple[int, int]]) -> NDArray[np.float64]:
    """1 for a term kept, 0 for piston and tilt (n <= 1) and the ``alignment`` terms named (e.g. power)."""
    return np.array([0.0 if n <= 1 or (n, m) in alignment else 1.0 for n, m in modes])


def stored_reference(mask: NDArray[np.bool_], pupil: tuple[float, float, float], modes: tuple[tuple[int, int], ...],
                     coefficients: NDArray[np.float64], covariance: NDArray[np.float64], *, method: str,
                     positions: int, unresolved_orders: tuple[int, ...], wavelength_nm: float,
                     date_utc: str) -> ReferenceCalibration:
    """The stored form of a reference found: its error over the pupil's whole disk, with the standard error per pixel.

    The coefficients are evaluated on every pixel of the basis's disk; the standard error per pixel
    is ``sqrt(b^T C b)``, ``b`` the basis at the pixel.
    """
    rows, cols = mask.shape
    cx, cy, radius = pupil
    row, col = np.indices((rows, cols), dtype=np.float64)
    u, v = (col - cx) / radius, (cy - row) / radius
    disk = u**2 + v**2 <= (1.0 + 0.5 / radius) ** 2
    basis = zernike_basis(modes, u[disk], v[disk])
    reference = np.full((rows, cols), np.nan)
    reference[disk] = basis @ coefficients
    stderr = np.full((rows, cols), np.nan)
    stderr[disk] = np.sqrt(np.clip(np.einsum("pi,ij,pj->p", basis, covariance, basis), 0.0, None))
    return ReferenceCalibration(
        method=method, positions=positions, date_utc=date_utc, wavelength_nm=float(wavelength_nm), grid=(rows, cols),
        pupil=tuple(float(p) for p in pupil), modes=modes, unresolved_orders=unresolved_orders, mask=mask,
        coefficients=coefficients, covariance=covariance, reference_waves=reference, reference_stderr_waves=stderr)
