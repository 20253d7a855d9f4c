"""``[shack_hartmann]``: a Shack-Hartmann sensor's geometry and how its spots become coefficients."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.config.schema import setting
from wavestack.pipeline.instrument import ShackHartmannSetup


@dataclass(frozen=True)
class ShackHartmannSettings:
    """``[shack_hartmann]``: the sensor's geometry and how its spots become coefficients.

    :meth:`setup` gives the processor's view of it
    (:class:`~wavestack.pipeline.instrument.ShackHartmannSetup`, where the fields are explained).
    """

    pitch_px: float = setting(minimum=4.0, maximum=4096.0, doc="lenslet pitch on the camera, pixels")
    focal_length_um: float = setting(minimum=1.0, maximum=1e6, doc="lenslet focal length, micrometres")
    pixel_um: float = setting(minimum=0.1, maximum=1000.0, doc="camera pixel pitch, micrometres")
    pupil_centre_px: tuple[float, float] = setting(doc="(col, row) of the pupil centre on the camera, pixels")
    pupil_radius_px: float = setting(minimum=1.0, maximum=1e5, doc="pupil radius on the camera, pixels")
    lattice: Literal["square", "hexagonal", "auto"] = setting(
        "square", doc="lenslet array: square, hexagonal (odd rows shifted half a pitch) or auto (from the first frame)")
    orientation_deg: float = setting(0.0, minimum=-180.0, maximum=180.0,
                                     doc="angle of the lenslet rows from the camera's columns, degrees")
    offset_px: tuple[float, float] = setting((0.0, 0.0), minimum=-0.5,
                                             doc="lenslet (0, 0) is centred at offset_px + pitch_px / 2, pixels")
    grid_shape: tuple[int, int] | None = setting(None, minimum=1, maximum=2048,
                                                 doc="(rows, cols) of lenslets; absent: as many as fit")
    modes: int = setting(36, minimum=3, maximum=231, doc="Noll terms reconstructed, from piston")
    ordering: Literal["noll"] = "noll"
    reference: Literal["ideal"] = setting("ideal", doc="reference spot positions: the lenslet centres")
    centroid_threshold: float = setting(0.1, minimum=0.0, maximum=0.95,
                                        doc="centre-of-gravity threshold, fraction of each window's peak")
    min_intensity: float = setting(0.0, minimum=0.0, doc="a thresholded spot below this is no spot, counts")
    lit_fraction: float = setting(0.9, minimum=0.0, maximum=1.0,
                                  doc="a lenslet is lit above this fraction of a typical full spot")
    min_lit_fraction: float = setting(0.5, minimum=0.0, maximum=1.0,
                                      doc="fewer lit pupil lenslets than this fraction: invalid result")
    max_condition: float = setting(1e4, minimum=1.0, doc="a reconstructor worse conditioned is refused")
    reconstructor_cache: int = setting(8, minimum=1, maximum=256, doc="lit-lenslet sets kept with their reconstructor")

    def gain_px(self, wavelength_nm: float) -> float:
        """Spot displacement per wavefront slope: ``f lambda / p**2``, pixels per (wave per pixel)."""
        return self.focal_length_um * (wavelength_nm * 1e-3) / self.pixel_um ** 2

    def setup(self, wavelength_nm: float) -> ShackHartmannSetup:
        """These settings as the Shack-Hartmann processor takes them, coefficients in waves of ``wavelength_nm``."""
        return ShackHartmannSetup(
            focal_length_um=self.focal_length_um, pixel_um=self.pixel_um, wavelength_nm=wavelength_nm,
            lattice=self.lattice, pitch_px=self.pitch_px, orientation_deg=self.orientation_deg,
            offset_px=self.offset_px, grid_shape=self.grid_shape, reference=self.reference,
            pupil_px=(*self.pupil_centre_px, self.pupil_radius_px), modes=self.modes, ordering=self.ordering,
            centroid_threshold=self.centroid_threshold, min_intensity=self.min_intensity,
            lit_fraction=self.lit_fraction, min_lit_fraction=self.min_lit_fraction,
            max_condition=self.max_condition, reconstructor_cache=self.reconstructor_cache)
