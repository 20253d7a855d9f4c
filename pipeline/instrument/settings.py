"""What an interferometer processor is told: phase method, aperture, unwrapping, data quality, fit.

One frozen value for every caller: the station turns its ``[processing]`` table into it
(``wavestack.config.ProcessingSettings.interferometer``), ``analyze`` its options or the
``--config`` file's table, ``replay`` and ``batch`` the recorded configuration. Two callers with
the same settings and the same frames get the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from ..aperture import DetectionSettings
from ..calibration import ReferenceCalibration
from ..zernike import ConicTest
from .fitter_source import FitSettings

__all__ = ["ConicNull", "InterferometerSettings", "QualitySettings"]


@dataclass(frozen=True)
class QualitySettings:
    """The per-pixel data-quality mask (:mod:`~wavestack.pipeline.instrument.quality`).

    Attributes
    ----------
    min_modulation : float
        A pixel whose modulation is below this fraction of the mean modulation over the aperture
        is marked (its phase noise is more than ``1 / min_modulation`` times the aperture's
        typical). 0 marks none.
    saturation_counts : float or None
        A pixel at or above this value in any frame of the set is marked saturated. None: the
        largest value of the frames' integer type (255 for 8-bit, 65535 for 16-bit containers;
        the station passes its camera's full scale, 4095 for Mono12); float frames are not checked.
    check_fringe_order : bool
        Mark pixels whose fringe order is not trusted: a jump of more than half a fringe against
        a good neighbour after unwrapping, or cut off from the aperture's main body by such jumps
        or by marked pixels.
    """

    min_modulation: float = 0.1
    saturation_counts: float | None = None
    check_fringe_order: bool = True


@dataclass(frozen=True)
class ConicNull:
    """A null subtracted before the fit: the wavefront a conic of constant ``conic`` shows in ``test``."""

    test: ConicTest
    conic: float


@dataclass(frozen=True)
class InterferometerSettings:
    """How interferograms become a map and coefficients (every field has the meaning of ``[processing]``).

    Attributes
    ----------
    method : {"psi", "carrier"}
        Phase-shifted sets, or one carrier-fringe frame per set.
    psi_algorithm : {"lsq", "four", "hariharan", "aia", "pca"}
        ``aia`` and ``pca`` estimate the steps from the data.
    steps_rad : tuple of float or None
        The phase steps (``lsq``; the starting guess of ``aia``); None: ``2 pi k / N``.
    direction : {"ccw", "cw"}
        Phase-step direction.
    carrier_sign : {1, -1}
        Sign of a carrier frame's phase (the tilt's direction).
    carrier_refresh_sets : int
        The carrier is searched for on the first frame, after an aperture change or an invalid
        result, and every this many frames; in between the last one is used. 1 searches every frame.
    aperture : {"detected", "circle"}
        The aperture choice (a user's mask is given to the processor instead).
    detection : DetectionSettings
    fit : FitSettings
    fit_decimation : int
        Unwrap and fit every n-th pixel in each direction.
    iou_threshold : float
        A detected aperture with a lower IoU against the one in use is a new aperture.
    watch_block_px : int
        Block size of the per-frame aperture watch.
    max_residues : int
        Residues allowed in a temporal step's difference map.
    unwrap_prefilter_px : float
        Smoothing before the spatial unwrap, full-resolution pixels.
    max_residual_waves : float or None
        A fit whose residual RMS exceeds this is invalid (None: no limit).
    quality : QualitySettings
    clip_sigma : float or None
        Spike clipping: pixels whose fit residual exceeds this many residual RMS are left out and
        the fit repeated (None: off). Default 6: a Gaussian noise sample lies beyond 6 sigma with
        probability 2e-9, so the clip takes no honest noise from a megapixel map, and it bounds
        the residual's PV at about 12 times its RMS.
    null : ConicNull or None
        A conic's null wavefront subtracted before the fit (``analyze --null-conic``).
    calibration : ReferenceCalibration or None
        The reference's error subtracted from every unwrapped map before the fit (``--calibration``);
        a set of another grid or aperture is an invalid result naming why, never resampled.
    """

    method: Literal["psi", "carrier"] = "psi"
    psi_algorithm: str = "lsq"
    steps_rad: tuple[float, ...] | None = None
    direction: Literal["ccw", "cw"] = "ccw"
    carrier_sign: Literal[1, -1] = 1
    carrier_refresh_sets: int = 32
    aperture: Literal["detected", "circle"] = "detected"
    detection: DetectionSettings = field(default_factory=DetectionSettings)
    fit: FitSettings = field(default_factory=FitSettings)
    fit_decimation: int = 1
    iou_threshold: float = 0.98
    watch_block_px: int = 4
    max_residues: int = 0
    unwrap_prefilter_px: float = 1.5
    max_residual_waves: float | None = None
    quality: QualitySettings = field(default_factory=QualitySettings)
    clip_sigma: float | None = 6.0
    null: ConicNull | None = None
    calibration: ReferenceCalibration | None = None
