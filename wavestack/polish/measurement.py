"""The loop's measurement: N live unwrapped maps averaged on one fixed aperture, in nm of surface.

A polishing job is only as good as the map it was computed from, so the measurement refuses
rather than guesses (:class:`UntrustedMeasurement`, naming the first problem): a result that is
invalid, older than the machine's last done, of another aperture than the other results, or of an
aperture other than the campaign's reference; fewer than the required results; a noise estimate
above its limit.

Units: a map in waves of wavefront becomes nm of surface as ``waves * wavelength_nm /
reflection_factor`` (2 for a surface seen in reflection at normal incidence, one pass). Each map
is cut to the aperture less ``edge_px`` pixels of its rim (the detected aperture's rim pixels carry
the lowest fringe modulation and the fit's largest residual, see docs/station.md; a solver would
chase them), then has the
configured target figure subtracted (if any) and piston, tip and tilt removed by a
least-squares plane on the aperture, before the maps are averaged: tilt and piston change from
result to result with alignment and vibration, and are not polished. A pixel the station's quality
mask left out of one map (NaN there) is averaged over the maps that measured it; a map leaving out
more than :data:`MAX_LEFT_OUT` of the aperture is refused. The noise estimate is the
standard error of the mean, ``sqrt(mean over the aperture of the per-pixel variance across the N
maps / N)``, with the unbiased (N - 1) variance: the spread that is left after PTT removal is
measurement noise plus any residual change during the average (both are what the solver must not
chase).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = ["MAX_LEFT_OUT", "ApertureKey", "MapSample", "Measurement", "UntrustedMeasurement", "average_surface",
           "remove_ptt", "surface_stats"]


class UntrustedMeasurement(ValueError):
    """A measurement the loop must not send a job on; the message says why."""


@dataclass(frozen=True)
class ApertureKey:
    """What identifies the aperture a map was measured on: its grid, pixel count and a hash of its mask.

    Attributes
    ----------
    shape : (int, int)
        The grid (rows, cols).
    pixels : int
        Pixels in the aperture.
    digest : str
        SHA-256 of the packed mask, hex, first 16 characters.

    Example
    -------
    >>> mask = np.zeros((4, 4), bool); mask[1:3, 1:3] = True
    >>> ApertureKey.of(mask).pixels
    4
    """

    shape: tuple[int, int]
    pixels: int
    digest: str

    @classmethod
    def of(cls, mask: NDArray[np.bool_]) -> ApertureKey:
        """The key of a boolean mask (rows, cols)."""
        mask = np.asarray(mask, dtype=bool)
        digest = hashlib.sha256(np.packbits(mask).tobytes() + repr(mask.shape).encode()).hexdigest()[:16]
        return cls((int(mask.shape[0]), int(mask.shape[1])), int(mask.sum()), digest)

    def to_json(self) -> dict[str, object]:
        """Plain JSON (the job file's ``aperture``)."""
        return {"shape": list(self.shape), "pixels": self.pixels, "mask_sha256_16": self.digest}


@dataclass(frozen=True, eq=False)
class MapSample:
    """One live result as the measurement sees it.

    Attributes
    ----------
    waves : ndarray (H, W) or None
        The unwrapped wavefront, waves, NaN outside the aperture (None: the result had none).
    valid : bool
    reason : str or None
        Why the result is invalid.
    aperture_id : int or None
        The station's aperture id of the result.
    exposure_time_ns : int
        Host time of the set's first frame (``time.time_ns``).
    """

    waves: NDArray[np.floating] | None
    valid: bool
    reason: str | None
    aperture_id: int | None
    exposure_time_ns: int


@dataclass(frozen=True, eq=False)
class Measurement:
    """A trusted surface measurement.

    Attributes
    ----------
    surface_nm : ndarray (H, W), float64
        Surface error, nm (target figure subtracted, PTT removed), NaN outside the aperture.
    mask : ndarray (H, W) of bool
        The aperture.
    aperture : ApertureKey
    rms_nm, pv_nm : float
        Of ``surface_nm`` on the aperture.
    noise_rms_nm : float
        Standard error of the average (module notes); NaN for a single map.
    count : int
        Maps averaged.
    oldest_exposure_ns, newest_exposure_ns : int
        Host times of the first and last map averaged.
    """

    surface_nm: NDArray[np.float64]
    mask: NDArray[np.bool_]
    aperture: ApertureKey
    rms_nm: float
    pv_nm: float
    noise_rms_nm: float
    count: int
    oldest_exposure_ns: int
    newest_exposure_ns: int

    def age_s(self, now_ns: int) -> float:
        """Seconds since the oldest map of the average was exposed."""
        return (now_ns - self.oldest_exposure_ns) * 1e-9


def remove_ptt(surface: NDArray[np.floating], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``surface`` less its least-squares plane (piston, tip, tilt) over ``mask``; NaN outside.

    Parameters
    ----------
    surface : ndarray (H, W)
    mask : ndarray (H, W) of bool
        At least 3 pixels, not all on one line.

    Example
    -------
    >>> rows, cols = np.mgrid[0:8, 0:8]
    >>> bool(np.allclose(remove_ptt(3.0 + 0.5 * rows - cols, np.ones((8, 8), bool)), 0.0))
    True
    """
    mask = np.asarray(mask, dtype=bool)
    rows, cols = np.nonzero(mask)
    values = np.asarray(surface, dtype=np.float64)[rows, cols]
    centre_r, centre_c = rows.mean(), cols.mean()  # centred: a better-conditioned design
    design = np.column_stack([np.ones(rows.size), rows - centre_r, cols - centre_c])
    coefficients, *_ = np.linalg.lstsq(design, values, rcond=None)
    out = np.full(mask.shape, np.nan)
    out[rows, cols] = values - design @ coefficients
    return out


def surface_stats(surface_nm: NDArray[np.floating], mask: NDArray[np.bool_]) -> tuple[float, float]:
    """(RMS about the mean, PV) of ``surface_nm`` on ``mask``, nm.

    Example
    -------
    >>> surface_stats(np.array([[1.0, -1.0]]), np.array([[True, True]]))
    (1.0, 2.0)
    """
    values = np.asarray(surface_nm, dtype=np.float64)[np.asarray(mask, dtype=bool)]
    if values.size == 0:
        return float("nan"), float("nan")
    return float(np.std(values)), float(np.ptp(values))


#: Largest share of the aperture one map may leave out (its quality mask's marks) and still be averaged.
MAX_LEFT_OUT = 0.05


def _check_samples(samples: Sequence[MapSample], min_count: int, not_before_ns: int | None) -> NDArray[np.bool_]:
    """The aperture of ``samples`` (the pixels any of them measured); raises UntrustedMeasurement naming the first problem.

    A map may leave out a few pixels the others measured (the station's quality mask: a spike, a
    saturated speck); more than :data:`MAX_LEFT_OUT` of the aperture, or another grid, is another
    aperture.
    """
    if len(samples) < min_count:
        raise UntrustedMeasurement(f"expected at least {min_count} valid results to average, got {len(samples)}")
    masks = []
    for index, sample in enumerate(samples):
        if not sample.valid or sample.waves is None:
            raise UntrustedMeasurement(f"result {index} of the average is invalid: {sample.reason or 'no map'}")
        if not_before_ns is not None and sample.exposure_time_ns < not_before_ns:
            raise UntrustedMeasurement(f"result {index} of the average was exposed before the machine's last done "
                                       f"({(not_before_ns - sample.exposure_time_ns) * 1e-9:.3f} s before)")
        if sample.aperture_id != samples[0].aperture_id:
            raise UntrustedMeasurement(f"aperture changed during the average: result {index} has aperture id "
                                       f"{sample.aperture_id}, expected {samples[0].aperture_id}")
        masks.append(np.isfinite(sample.waves))
        if masks[-1].shape != masks[0].shape:
            raise UntrustedMeasurement(f"aperture changed during the average: result {index}'s map is "
                                       f"{masks[-1].shape}, expected {masks[0].shape}")
    mask = np.logical_or.reduce(masks)
    for index, finite in enumerate(masks):
        left_out = int(np.count_nonzero(mask & ~finite))
        if left_out > MAX_LEFT_OUT * mask.sum():
            raise UntrustedMeasurement(f"aperture changed during the average: result {index}'s map leaves out "
                                       f"{left_out} of the {int(mask.sum())} pixels the others measured")
    if mask.sum() < 3:
        raise UntrustedMeasurement(f"the aperture has {int(mask.sum())} pixels; expected at least 3")
    return mask


def average_surface(samples: Sequence[MapSample], *, wavelength_nm: float, reflection_factor: float,
                    min_count: int, reference: ApertureKey | None = None, target_nm: NDArray[np.floating] | None = None,
                    not_before_ns: int | None = None, max_noise_rms_nm: float | None = None,
                    edge_px: int = 0) -> Measurement:
    """Average live maps into a trusted surface measurement (pure; module notes).

    Parameters
    ----------
    samples : sequence of MapSample
        At least ``min_count``, all valid, all of one aperture.
    wavelength_nm : float
        The test wavelength, nm.
    reflection_factor : float
        Wavefront per surface (2 in reflection at normal incidence).
    min_count : int
    reference : ApertureKey, optional
        The campaign's aperture; a different one is refused.
    target_nm : ndarray (H, W), optional
        The target figure, nm of surface, subtracted before PTT removal (NaN allowed outside the
        aperture; required finite on it).
    not_before_ns : int, optional
        The machine's last done: a map exposed before it shows the surface before polishing.
    max_noise_rms_nm : float, optional
        Refuse a noisier average.
    edge_px : int
        Pixels taken off the aperture's rim (a binary erosion with a 3 x 3 square, ``edge_px``
        times) before anything else.

    Returns
    -------
    Measurement

    Raises
    ------
    UntrustedMeasurement
        Module notes.

    Example
    -------
    >>> waves = np.zeros((8, 8)); waves[0] = np.nan
    >>> sample = MapSample(waves, True, None, 0, 0)
    >>> average_surface([sample] * 3, wavelength_nm=600.0, reflection_factor=2.0, min_count=3).rms_nm
    0.0
    """
    if not (wavelength_nm > 0 and reflection_factor > 0):
        raise ValueError(f"wavelength_nm and reflection_factor must be > 0, got {wavelength_nm}, {reflection_factor}")
    mask = _check_samples(samples, min_count, not_before_ns)
    if edge_px > 0:
        mask = ndimage.binary_erosion(mask, structure=np.ones((3, 3), bool), iterations=edge_px)
        if mask.sum() < 3:
            raise UntrustedMeasurement(f"the aperture less {edge_px} rim pixels has {int(mask.sum())} pixels; "
                                       "expected at least 3")
    key = ApertureKey.of(mask)
    if reference is not None and key != reference:
        raise UntrustedMeasurement(f"aperture changed: {key.pixels} pixels (mask {key.digest}), expected the "
                                   f"campaign's {reference.pixels} pixels (mask {reference.digest})")
    target = None
    if target_nm is not None:
        target = np.asarray(target_nm, dtype=np.float64)
        if target.shape != mask.shape or not np.all(np.isfinite(target[mask])):
            raise UntrustedMeasurement(f"the target figure {target.shape} must be finite on the {mask.shape} aperture")
    scale = wavelength_nm / reflection_factor
    maps = np.empty((len(samples), int(mask.sum())))
    for index, sample in enumerate(samples):
        assert sample.waves is not None  # checked above
        surface = np.asarray(sample.waves, dtype=np.float64) * scale
        if target is not None:
            surface = surface - target
        maps[index] = remove_ptt(surface, mask & np.isfinite(surface))[mask]  # NaN where this map left a pixel out
    measured = np.isfinite(maps)
    per_pixel = measured.sum(axis=0)  # >= 1: the aperture is the pixels some map measured
    mean = np.where(measured, maps, 0.0).sum(axis=0) / per_pixel
    count = len(samples)
    noise = float("nan")
    if count > 1:  # the standard error of each pixel's mean, over the pixels measured at least twice
        spread = np.where(measured, maps - mean, 0.0)
        twice = per_pixel > 1
        variance = (spread**2).sum(axis=0)[twice] / (per_pixel[twice] - 1)
        noise = float(np.sqrt(np.mean(variance / per_pixel[twice])))
    if max_noise_rms_nm is not None and not noise <= max_noise_rms_nm and count > 1:
        raise UntrustedMeasurement(f"noise of the average {noise:.3g} nm RMS exceeds max_noise_rms_nm = "
                                   f"{max_noise_rms_nm:g}")
    surface_nm = np.full(mask.shape, np.nan)
    surface_nm[mask] = mean
    rms, pv = surface_stats(surface_nm, mask)
    times = [s.exposure_time_ns for s in samples]
    return Measurement(surface_nm, mask, key, rms, pv, noise, count, min(times), max(times))
