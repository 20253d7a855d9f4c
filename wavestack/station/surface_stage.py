"""The surface figures of live results: the pipeline's ``SurfaceAnalyzer`` on the station's maps.

Each result's unwrapped wavefront (waves, on the fit grid) becomes surface height (``waves *
wavelength * surface_factor``, nm) and is measured on a sub-grid of at most ``max_pixels``
pixels (every k-th pixel each way): the form figures, PVr and the drawing's verdict every
result, the FFT-based figures (PSD, filter) every ``spectra_every``-th result. The analyzer is
built once per measured area and kept while the area stays the same; a new aperture (or new
drop-outs) builds a new one. The stage is a plain object, called on the station's processing
thread; what it makes is a frozen :class:`SurfaceRecord`.
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import SurfaceAnalyzer, SurfaceRequest
from wavestack.pipeline.surface import FormFigures, RobustPV, SpecVerdict

if TYPE_CHECKING:  # only for annotations
    from wavestack.config import StationConfig

__all__ = ["SurfaceRecord", "SurfaceStage", "surface_stage"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SurfaceRecord:
    """The surface figures of one live result.

    Attributes
    ----------
    form : FormFigures
        nm of surface.
    pvr : RobustPV
        nm of surface.
    wavelength_nm : float
        The fringes' wavelength.
    verdict : SpecVerdict or None
        Against the station's drawing tolerance, if one is configured.
    band_rms_nm : float or None
        The PSD's band RMS, on the results that computed spectra.
    slope_rms_urad : float or None
    stride : int
        The sub-grid the figures were taken on (every ``stride``-th pixel of the fit grid).
    """

    form: FormFigures
    pvr: RobustPV
    wavelength_nm: float
    verdict: SpecVerdict | None = None
    band_rms_nm: float | None = None
    slope_rms_urad: float | None = None
    stride: int = 1

    def to_json(self) -> dict[str, object]:
        """The keys a JSON line and the live view carry."""
        record: dict[str, object] = {**self.form.as_dict(self.wavelength_nm), "pvr_nm": self.pvr.pvr,
                                     "stride": self.stride}
        if self.verdict is not None:
            record["spec"] = {"notation": self.verdict.tolerance.notation, "passed": self.verdict.passed,
                              "limiting": self.verdict.limiting.quantity}
        if self.band_rms_nm is not None:
            record["band_rms_nm"] = self.band_rms_nm
        if self.slope_rms_urad is not None:
            record["slope_rms_urad"] = self.slope_rms_urad
        return record


class SurfaceStage:
    """Measures the surface figures of the station's maps.

    Parameters
    ----------
    request : SurfaceRequest
    wavelength_nm : float
        The test wavelength (the maps are in waves of it).
    surface_factor : float
        Surface height per wavefront (0.5 in reflection at normal incidence).
    pixel_mm : float or None
        The fit grid's pixel pitch at the optic, mm (needed by PSD, slope and filters).
    max_pixels : int
        The largest number of pixels the figures are taken on (a sub-grid beyond it).
    spectra_every : int
        The FFT-based figures every this many results (1: every result).
    """

    def __init__(self, request: SurfaceRequest, *, wavelength_nm: float, surface_factor: float = 0.5,
                 pixel_mm: float | None = None, max_pixels: int = 40000, spectra_every: int = 10) -> None:
        self.request = request
        self._scale = wavelength_nm * surface_factor
        self._pixel_mm = pixel_mm
        self._max_pixels = max_pixels
        self._spectra_every = max(1, spectra_every)
        self._analyzer: SurfaceAnalyzer | None = None
        self._key: tuple[int, bytes] | None = None  # the sub-grid's stride and its measured pixels' digest

    def record(self, index: int, waves: NDArray[np.floating]) -> SurfaceRecord | None:
        """:meth:`measure`, or None (logged once per measured area) when the map cannot carry the figures."""
        try:
            return self.measure(index, waves)
        except ValueError as error:
            if self._key is not None:  # the first failure on this area: say why once
                logger.warning("surface figures: none on this aperture: %s", error)
                self._key = None
                self._analyzer = None
            return None

    def measure(self, index: int, waves: NDArray[np.floating]) -> SurfaceRecord:
        """The figures of result ``index``'s map (waves, NaN outside the measured pixels).

        Raises
        ------
        ValueError
            If the map cannot carry the figures (too few pixels, a request its sampling cannot serve).
        """
        stride = self._key[0] if self._key is not None else 0
        valid = np.isfinite(waves[::stride, ::stride]) if stride else None
        if valid is None or _digest(stride, valid) != self._key or self._analyzer is None:
            stride = max(1, math.ceil(math.sqrt(np.count_nonzero(np.isfinite(waves)) / self._max_pixels)))
            valid = np.isfinite(waves[::stride, ::stride])
            pixel = None if self._pixel_mm is None else self._pixel_mm * stride
            self._analyzer = SurfaceAnalyzer(valid, self.request, pixel_mm=pixel)
            self._key = _digest(stride, valid)
        surface_nm = waves[::stride, ::stride] * self._scale  # NaN stays NaN: the analyzer reads the measured pixels
        figures = self._analyzer.measure(surface_nm, spectral=index % self._spectra_every == 0)
        return SurfaceRecord(
            form=figures.form, pvr=figures.pvr, wavelength_nm=figures.wavelength_nm, verdict=figures.verdict,
            band_rms_nm=figures.band.rms_nm if figures.band is not None else None,
            slope_rms_urad=figures.slope.figures().rms_urad if figures.slope is not None else None, stride=stride)


def _digest(stride: int, valid: NDArray[np.bool_]) -> tuple[int, bytes]:
    """What identifies a measured area on the sub-grid: its stride and a digest of its mask."""
    text = np.packbits(valid).tobytes() + str(valid.shape).encode("ascii")
    return stride, hashlib.blake2b(text, digest_size=16).digest()


def surface_stage(config: StationConfig) -> SurfaceStage | None:
    """The stage of a station's ``[surface]`` settings; None when off (or for a Shack-Hartmann station)."""
    settings = config.surface
    if not settings.enabled or config.shack_hartmann is not None:
        return None
    decimation = config.processing.fit_decimation
    return SurfaceStage(settings.request(config.source), wavelength_nm=config.station.wavelength_nm,
                        surface_factor=settings.surface_factor,
                        pixel_mm=None if settings.pixel_mm is None else settings.pixel_mm * decimation,
                        max_pixels=settings.max_pixels, spectra_every=settings.spectra_every)
