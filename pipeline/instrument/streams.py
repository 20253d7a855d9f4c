"""The processor of a settings' kind, a stream of one set (what ``analyze`` measures), and a measured map.

``analyze`` reads one set from files and measures it exactly as the station measures a set of a
live stream: a fresh processor of the same kind and settings, given one set. The first set of any
stream is processed this way (spatial unwrap, the aperture adopted at once), so a set measured
alone and the same set measured first in a stream give the same numbers; later sets of a stream
differ from it only where their state does (a held aperture, a temporal unwrap).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from .carrier import CarrierProcessor
from .fitter_source import FitterSource, SyncFitterSource
from .outcome import InterferometerOutcome
from .phase_shifting import PhaseShiftingProcessor
from .quality import LOW_MODULATION, OUTSIDE, PixelQuality
from .settings import InterferometerSettings
from .tracking import null_waves
from .statistics import MapStatistics, clip_spikes, map_pv, pvr_analyzer, robust_pv

__all__ = ["measure_map", "measure_set", "processor_for"]


def processor_for(settings: InterferometerSettings, fitters: FitterSource, *,
                  mask: NDArray[np.bool_] | None = None, residual_map: bool = False
                  ) -> PhaseShiftingProcessor | CarrierProcessor:
    """The processor of ``settings.method``: phase shifting (``psi``) or the carrier method (``carrier``);
    ``mask`` and ``residual_map`` as :class:`~.interferometer.InterferometerProcessor` takes them."""
    if settings.method == "carrier":
        return CarrierProcessor(settings, fitters, mask=mask, residual_map=residual_map)
    return PhaseShiftingProcessor(settings, fitters, mask=mask, residual_map=residual_map)


def measure_set(frames: Sequence[NDArray[np.generic]], settings: InterferometerSettings, *,
                mask: NDArray[np.bool_] | None = None) -> InterferometerOutcome:
    """One set measured as the first of a stream, its fitter built at once (module notes).

    Parameters
    ----------
    frames : sequence of ndarray, each (rows, cols)
        A phase-shifted set in stepping order, or one carrier frame.
    settings : InterferometerSettings
    mask : ndarray of bool, optional
        A user's aperture.

    Returns
    -------
    InterferometerOutcome

    Raises
    ------
    ValueError
        A set of the wrong length, or a mask of another shape.

    Example
    -------
    >>> from wavestack.pipeline.instrument import FitSettings
    >>> rows, cols = np.mgrid[:96, :96]
    >>> rho2 = ((rows - 47.5) ** 2 + (cols - 47.5) ** 2) / 40.0**2
    >>> frames = [np.where(rho2 < 1, 100 + 80 * np.cos(2 * np.pi * 0.2 * rho2 + k * np.pi / 2), 10)
    ...           for k in range(4)]
    >>> outcome = measure_set(frames, InterferometerSettings(fit=FitSettings(method="circle", modes=10)))
    >>> outcome.valid, outcome.method, outcome.quality.excluded
    (True, 'lsq', 0)
    """
    processor = processor_for(settings, SyncFitterSource(settings.fit), mask=mask, residual_map=True)
    return processor.process(list(frames))


def measure_map(waves: NDArray[np.floating], aperture: Aperture, measured: NDArray[np.bool_],
                settings: InterferometerSettings) -> InterferometerOutcome:
    """A measured map (a file's, in waves) through the fit stage the processors end with.

    Fit on exactly the ``measured`` pixels (the file's valid ones), less a null test's wavefront
    (``settings.null``), then spike clipping, PV and PVr as for interferograms (``settings.fit``,
    ``settings.clip_sigma``). Pixels of the outline without
    a measurement (drop-outs) are marked low modulation: the instrument found nothing to measure
    there. Nothing is filled.

    Parameters
    ----------
    waves : ndarray, shape (rows, cols)
        The map, waves (values outside ``measured`` are ignored).
    aperture : Aperture
        Its outline (the pupil and a mapped method's domain).
    measured : ndarray of bool, shape (rows, cols)
        The pixels holding a measurement, inside ``aperture``.
    settings : InterferometerSettings

    Returns
    -------
    InterferometerOutcome
        ``method`` and ``aperture_choice`` are ``"file"``.

    Raises
    ------
    IllConditionedBasis
        The fit's basis cannot be carried by these pixels (its advice names the remedies).
    """
    measured = np.asarray(measured, dtype=bool) & aperture.mask
    flags = np.where(aperture.mask, np.where(measured, 0, LOW_MODULATION), OUTSIDE).astype(np.uint8)
    choice = SyncFitterSource(settings.fit).new_aperture(aperture, fit_mask=measured)
    raw = np.where(measured, np.asarray(waves, dtype=np.float64), np.nan)
    to_fit = raw if settings.null is None else raw - null_waves(aperture, settings.null)
    tick = time.perf_counter()
    fit = choice.fitter.fit(to_fit, nan_policy="omit", residual=True)
    if settings.clip_sigma is not None:
        fit, _ = clip_spikes(choice.fitter, to_fit, flags, fit, settings.clip_sigma, residual=True)
    assert fit.residual_pv is not None
    pvr = robust_pv(pvr_analyzer(measured, settings.fit.remove, settings.fit.dtype), to_fit)
    statistics = MapStatistics(fit.residual_rms, fit.residual_pv, map_pv(to_fit, fit.removed), pvr)
    if not np.array_equal(np.isnan(raw), np.isnan(to_fit)):  # clipped pixels leave the measured map too
        raw[np.isnan(to_fit)] = np.nan
    return InterferometerOutcome(True, None, fit.coefficients, fit, choice, aperture, True, None, raw, flags,
                                 PixelQuality.of(flags), statistics, {"fit": time.perf_counter() - tick},
                                 method="file", aperture_choice="file")
