"""What a processor returns for one set: a frozen outcome, and the small records every instrument shares.

:class:`InstrumentOutcome` is what the station's result is made of, whichever the instrument
(an interferometer's :class:`InterferometerOutcome` here, a Shack-Hartmann processor's slope
outcome beside it); :class:`~.records.ApertureRecord`, :class:`~.statistics.MapStatistics` and
:class:`~.quality.PixelQuality` are the records both kinds fill. Nothing here does I/O or knows a device.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture, EdgeCircle
from ..fit import FitResult
from .fitter_source import FitterChoice
from .quality import PixelQuality
from .records import ApertureRecord, FitDiagnostics
from .statistics import MapStatistics

__all__ = ["InstrumentOutcome", "InterferometerOutcome"]


class InstrumentOutcome(Protocol):
    """What every processor's outcome tells the result (read-only)."""

    @property
    def valid(self) -> bool: ...
    @property
    def reason(self) -> str | None: ...
    @property
    def coefficients_waves(self) -> NDArray[np.float64] | None: ...
    @property
    def statistics(self) -> MapStatistics: ...
    @property
    def quality(self) -> PixelQuality | None: ...
    @property
    def fitter_kind(self) -> str | None: ...
    @property
    def fitter_fallback(self) -> bool: ...
    @property
    def normalisation(self) -> str: ...
    @property
    def aperture_record(self) -> ApertureRecord | None: ...
    @property
    def aperture_changed(self) -> bool: ...
    @property
    def unwrap_path(self) -> str | None: ...
    @property
    def timings_s(self) -> dict[str, float]: ...
    @property
    def new_aperture_mask(self) -> NDArray[np.bool_] | None: ...
    @property
    def calibration(self) -> str | None: ...


@dataclass(frozen=True, eq=False)
class InterferometerOutcome:
    """What one set of interferograms gave.

    Attributes
    ----------
    valid : bool
        False when no trustworthy coefficients came out; ``reason`` says why.
    reason : str or None
    coefficients_waves : ndarray, shape (modes,) or None
        Zernike coefficients of the wavefront in waves, the fitter's ordering and normalisation.
    fit : FitResult or None
        The fit (after spike clipping), with its residual map.
    choice : FitterChoice or None
        The fitter used (kind, fallback flag, aperture id).
    aperture : Aperture or None
        Full-resolution aperture of this set.
    aperture_changed : bool
        True when this set started a new aperture (a new fitter).
    unwrap_path : str or None
        "spatial" or "temporal".
    waves : ndarray, shape (rows, cols) of the fit grid, or None
        The unwrapped wavefront on the fit grid (every ``fit_decimation``-th pixel), waves, NaN
        outside the aperture and at every pixel the quality mask left out (never filled).
    flags : ndarray of uint8, same shape, or None
        The quality marks of each pixel (:mod:`~wavestack.pipeline.instrument.quality`).
    quality : PixelQuality or None
        Their counts.
    statistics : MapStatistics
        Residual RMS and PV, PV and PVr over the pixels used (NaN when invalid).
    timings_s : dict
        Seconds per stage: phase, aperture, unwrap, quality, fit, statistics.
    method : str or None
        The phase algorithm (``lsq``, ``hariharan``, ``aia``, ``carrier``, ...).
    steps_rad : ndarray or None
        The phase steps used (estimated for ``aia`` and ``pca``).
    carrier : (fx, fy) or None
        The carrier of a carrier frame, cycles per pixel.
    aperture_choice : str or None
        ``detected``, ``circle`` or ``mask``.
    edge : EdgeCircle or None
        The circle fitted to the detected edge, with its uncertainties (pixels).
    error : ValueError or None
        What made the outcome invalid, for a caller that wants more than ``reason`` (e.g. the
        advice of an :class:`~wavestack.pipeline.IllConditionedBasis`).
    calibration : str or None
        The content hash (SHA-256, hex) of the reference calibration subtracted from ``waves``
        before the fit; None when none was.
    """

    valid: bool
    reason: str | None
    coefficients_waves: NDArray[np.float64] | None = None
    fit: FitResult | None = None
    choice: FitterChoice | None = None
    aperture: Aperture | None = None
    aperture_changed: bool = False
    unwrap_path: str | None = None
    waves: NDArray[np.float64] | None = None
    flags: NDArray[np.uint8] | None = None
    quality: PixelQuality | None = None
    statistics: MapStatistics = field(default_factory=MapStatistics.none)
    timings_s: dict[str, float] = field(default_factory=dict)
    method: str | None = None
    steps_rad: NDArray[np.float64] | None = None
    carrier: tuple[float, float] | None = None
    aperture_choice: str | None = None
    edge: EdgeCircle | None = None
    error: ValueError | None = None
    calibration: str | None = None

    # -- what the result records (pure views of the fields above)
    @property
    def fitter_kind(self) -> str | None:
        return self.choice.kind if self.choice is not None else None

    @property
    def fitter_fallback(self) -> bool:
        return bool(self.choice and self.choice.fallback)

    @property
    def residual_rms(self) -> float:
        return self.statistics.residual_rms

    @property
    def residual_pv(self) -> float:
        return self.statistics.residual_pv

    @property
    def normalisation(self) -> str:
        return self.fit.basis.normalisation if self.fit is not None else "rms"

    @property
    def diagnostics(self) -> FitDiagnostics | None:
        if self.choice is None:
            return None
        d = self.choice.fitter.diagnostics
        return FitDiagnostics(gram_condition=d.gram_condition, flips=d.flips, max_beltrami=d.max_beltrami)

    @property
    def aperture_record(self) -> ApertureRecord | None:
        if self.aperture is None:
            return None
        return ApertureRecord(id=self.choice.aperture_id if self.choice else None, changed=self.aperture_changed,
                              topology=self.aperture.describe(), components=self.aperture.components,
                              valid_pixels=int(self.aperture.mask.sum()))

    @property
    def new_aperture_mask(self) -> NDArray[np.bool_] | None:
        """The full-resolution mask when this set started a new aperture (for the recording)."""
        return self.aperture.mask if self.aperture_changed and self.aperture is not None else None
