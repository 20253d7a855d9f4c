"""``[shack_hartmann]``: a Shack-Hartmann sensor's geometry and how its spots become coefficients."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from wavestack.config.schema import setting
from wavestack.pipeline import LensletGrid


@dataclass(frozen=True)
class ShackHartmannSettings:
    """``[shack_hartmann]``: the sensor's geometry and how its spots become coefficients."""

    pitch_px: float = setting(minimum=4.0, maximum=4096.0, doc="lenslet pitch on the camera, pixels")
    focal_length_um: float = setting(minimum=1.0, maximum=1e6, doc="lenslet focal length, micrometres")
    pixel_um: float = setting(minimum=0.1, maximum=1000.0, doc="camera pixel pitch, micrometres")
    pupil_centre_px: tuple[float, float] = setting(doc="(col, row) of the pupil centre on the camera, pixels")
    pupil_radius_px: float = setting(minimum=1.0, maximum=1e5, doc="pupil radius on the camera, pixels")
    offset_px: tuple[float, float] = setting((0.0, 0.0), minimum=-0.5,
                                             doc="(col, row) of the top-left corner of lenslet (0, 0), pixels")
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

    def grid_for(self, frame_shape: tuple[int, int]) -> LensletGrid:
        """The lenslet grid on frames of ``frame_shape`` ``(rows, cols)``.

        Without ``grid_shape`` it holds every whole lenslet between the offset and the frame's far
        pixel edges (pixel centres are integers, so the frame spans ``[-0.5, size - 0.5]``).

        Raises
        ------
        ValueError
            If no lenslet fits, or a subaperture window leaves the frame.
        """
        if self.grid_shape is not None:
            shape = self.grid_shape
        else:
            shape = tuple(int(math.floor((size - 0.5 - start) / self.pitch_px))
                          for size, start in zip(frame_shape, self.offset_px[::-1]))
            if min(shape) < 1:
                raise ValueError(f"no whole lenslet of pitch {self.pitch_px} px from {self.offset_px} "
                                 f"fits in a {frame_shape} frame")
        grid = LensletGrid(pitch_px=self.pitch_px, offset_px=self.offset_px, shape=shape)
        grid.check_fits(frame_shape)
        return grid
