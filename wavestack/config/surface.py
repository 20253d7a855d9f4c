"""``[surface]``: the surface figures of every live result (ISO form, PVr, the drawing's verdict, PSD, slope).

Off unless ``enabled``. The maps are the station's unwrapped wavefront on the fit grid, made
surface height by ``surface_factor``; the figures are taken on at most ``max_pixels`` of its
pixels (every k-th pixel each way beyond), the FFT-based ones (the PSD) every
``spectra_every``-th result. The PSD and slope need the camera pixel's pitch at the optic.
"""

from __future__ import annotations

from dataclasses import dataclass

from wavestack.config.schema import ConfigError, setting
from wavestack.pipeline import SurfaceRequest, ToleranceError, parse_form_tolerance

__all__ = ["SurfaceSettings"]


@dataclass(frozen=True)
class SurfaceSettings:
    """``[surface]``: the surface figures of every live result."""

    enabled: bool = setting(False, doc="measure the surface figures of every result")
    spec: str | None = setting(None, doc="the drawing's form tolerance, e.g. '3/2(0.5/0.2)' (ISO 10110-5)")
    surface_factor: float = setting(0.5, minimum=0.01, maximum=10.0, doc="surface height per wavefront")
    pixel_mm: float | None = setting(None, minimum=1e-6, maximum=100.0,
                                     doc="camera pixel pitch at the optic, mm (for the PSD and slope)")
    max_pixels: int = setting(20000, minimum=1000, maximum=10_000_000,
                              doc="figures on at most this many pixels of the fit grid (a sub-grid beyond)")
    spectra_every: int = setting(10, minimum=1, maximum=100_000, doc="the PSD every this many results")
    psd: bool = setting(False, doc="the PSD's band RMS and power law (needs pixel_mm)")
    psd_band_mm: tuple[float, ...] = setting((), minimum=1e-6, maximum=1e6,
                                             doc="the band as two spatial periods, mm (default: all resolved)")
    slope_length_mm: float | None = setting(None, minimum=1e-6, maximum=1e4,
                                            doc="RMS slope over this integration length, mm (needs pixel_mm)")

    def request(self, source: str) -> SurfaceRequest:
        """The pipeline's request for these settings.

        Raises
        ------
        ConfigError
            For a tolerance that cannot be read, a band that is not two periods, or a PSD or
            slope without ``pixel_mm``.
        """
        try:
            tolerance = parse_form_tolerance(self.spec) if self.spec is not None else None
        except ToleranceError as error:
            raise ConfigError(f"{source}: [surface] spec: {error}") from None
        if self.psd_band_mm and (len(self.psd_band_mm) != 2 or self.psd_band_mm[0] == self.psd_band_mm[1]):
            raise ConfigError(f"{source}: [surface] psd_band_mm = {list(self.psd_band_mm)}: expected two different "
                              "spatial periods in mm")
        band = (1.0 / max(self.psd_band_mm), 1.0 / min(self.psd_band_mm)) if self.psd_band_mm else None
        if (self.psd or band or self.slope_length_mm) and self.pixel_mm is None:
            raise ConfigError(f"{source}: [surface] the PSD and slope need pixel_mm, the camera pixel's pitch at "
                              "the optic in mm")
        return SurfaceRequest(tolerance=tolerance, psd=self.psd or band is not None, band_per_mm=band,
                              slope_length_mm=self.slope_length_mm)
