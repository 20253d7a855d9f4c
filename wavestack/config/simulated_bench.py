"""The simulated bench's tables of a station file: ``[optic]`` (with ``[optic.aperture]``, ``[optic.surface]``,
``[optic.reference]``, ``[optic.ball]``), ``[bench]``, ``[lenslets]``.

What a station file may say about the test optic, the piezo's coupling to the fringes and the
lenslet array of a simulated Shack-Hartmann camera: settings only, with the bounds a key must
meet. The simulator starter (``wavestack.simulated``) turns them into the simulators' own settings,
field by field, where the simulators' checks across keys run (an annulus whose obscuration leaves
the outer circle, a roughness correlation shorter than a pixel). The meaning of each key is the
simulator's: ``wavestack.simulators.optic``, ``.surface_settings``, ``.aperture_shape``, ``.spots``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.config.schema import setting

__all__ = ["ApertureShapeSettings", "BallSimulatorSettings", "BenchSimulatorSettings", "LensletSimulatorSettings", "OpticSimulatorSettings",
           "ReferenceSimulatorSettings", "SurfaceSimulatorSettings"]

BitDepth = Literal[8, 12, 16]


@dataclass(frozen=True)
class ApertureShapeSettings:
    """``[optic.aperture]``: the test optic's clear aperture on the camera, pixels ``(col, row)``."""

    kind: Literal["circle", "annulus", "ellipse", "rectangle", "polygon"] = "circle"
    centre_px: tuple[float, float] = (512.0, 512.0)
    radius_px: float = setting(400.0, minimum=0.0, doc="circle, or the annulus's outer circle")
    inner_radius_px: float = setting(0.0, minimum=0.0, doc="annulus: the obscuration's radius")
    obscuration_centre_px: tuple[float, float] | None = setting(None, doc="annulus: default centre_px")
    semi_axes_px: tuple[float, float] = setting((400.0, 300.0), doc="ellipse semi-axes, rectangle half-widths")
    rotation_deg: float = 0.0
    vertices_px: tuple[tuple[float, float], ...] = setting((), doc="polygon: at least 3 (col, row) vertices")


@dataclass(frozen=True)
class SurfaceSimulatorSettings:
    """``[optic.surface]``: the optic's surface as a height map in nm that a simulated machine polishes."""

    zernike_nm: tuple[float, ...] = setting((), doc="Noll c1, c2, ... of the surface, nm of height")
    map_file: str | None = setting(None, doc="a measured map (.dat, .datx, 4D .h5, .npy in nm)")
    map_rms_nm: float | None = setting(None, minimum=0.0, doc="scale the map to this RMS, nm")
    roughness_rms_nm: float = setting(0.0, minimum=0.0, doc="mid-spatial roughness, nm RMS")
    roughness_correlation_mm: float = setting(1.0, minimum=0.0, doc="its correlation length, mm")
    seed: int = setting(0, minimum=0)
    pixel_mm: float = setting(0.1, minimum=0.0, doc="a camera pixel on the optic, mm")
    reflection_factor: float = setting(2.0, minimum=0.0, doc="wavefront per surface height (2: reflection)")
    wavelength_nm: float = setting(632.8, minimum=0.0, doc="default: [station] wavelength_nm")


@dataclass(frozen=True)
class ReferenceSimulatorSettings:
    """``[optic.reference]``: the interferometer's reference error, nm of wavefront, fixed in the camera's frame."""

    zernike_nm: tuple[float, ...] = setting((), doc="Noll c1, c2, ... of the reference's error, nm of wavefront")
    map_file: str | None = setting(None, doc="a measured map (.dat, .datx, 4D .h5, .npy in nm)")
    map_rms_nm: float | None = setting(None, minimum=0.0, doc="scale the map to this RMS, nm")
    wavelength_nm: float = setting(632.8, minimum=0.0, doc="default: [station] wavelength_nm")


@dataclass(frozen=True)
class BallSimulatorSettings:
    """``[optic.ball]``: a calibration ball at the confocal position (the random ball test), re-seated at random."""

    figure_nm: float = setting(10.0, minimum=0.0, doc="the ball's figure over the whole sphere, nm RMS of wavefront")
    cap_half_angle_deg: float = setting(30.0, minimum=0.0, maximum=90.0, doc="the cap the interferometer sees")
    terms: int = setting(40, minimum=1, doc="plane waves of the random figure")
    max_frequency: float = setting(12.0, minimum=1.0, doc="largest spatial frequency, radians per radian")
    seed: int = setting(0, minimum=0)
    wavelength_nm: float = setting(632.8, minimum=0.0, doc="default: [station] wavelength_nm")


@dataclass(frozen=True)
class OpticSimulatorSettings:
    """``[optic]``: the simulated test optic, its fringes and how the camera sees them."""

    aperture: ApertureShapeSettings = ApertureShapeSettings()
    zernike_waves: tuple[float, ...] = setting((0.0, 0.0, 0.0, 0.5, 0.1, -0.2, 0.1, 0.05, 0.03, -0.02, 0.25),
                                               doc="Noll c1, c2, ... of the wavefront, waves")
    drift_waves_per_s: tuple[float, ...] = setting((), doc="drift of each coefficient, waves/s")
    carrier_cycles: tuple[float, float] = setting((0.0, 0.0), doc="tilt fringes across the frame (x, y)")
    background: float = setting(0.45, minimum=0.0, doc="fraction of full scale")
    modulation: float = setting(0.4, minimum=0.0, doc="fraction of full scale")
    halo: float = setting(0.03, minimum=0.0, doc="level outside the aperture, fraction of full scale")
    noise_rms: float = setting(0.005, minimum=0.0, doc="read noise, fraction of full scale")
    vibration_rms_rad: float = setting(0.0, minimum=0.0, doc="piston jitter, rad RMS")
    vibration_hz: float = setting(0.0, minimum=0.0, doc="0: white jitter")
    bit_depth: BitDepth = 12
    seed: int = setting(0, minimum=0)
    surface: SurfaceSimulatorSettings | None = None
    reference: ReferenceSimulatorSettings | None = None
    ball: BallSimulatorSettings | None = None


@dataclass(frozen=True)
class BenchSimulatorSettings:
    """``[bench]``: how the simulated piezo moves the fringes."""

    axis: str = setting("x", doc="the controller output driving the reference mirror")
    radians_per_volt: float = setting(0.05, doc="true phase shift per volt (double pass included)")


@dataclass(frozen=True)
class LensletSimulatorSettings:
    """``[lenslets]``: the simulated lenslet array, its relay and the Shack-Hartmann camera's spots."""

    pitch_px: float = setting(25.0, minimum=4.0, doc="lenslet pitch on the camera, pixels")
    offset_px: tuple[float, float] = setting((0.0, 0.0), minimum=-0.5, doc="corner of lenslet (0, 0), (col, row)")
    grid_shape: tuple[int, int] | None = setting(None, minimum=1, doc="(rows, cols); default: as many as fit")
    lattice: Literal["square", "hexagonal"] = "square"
    orientation_deg: float = setting(0.0, doc="angle of the lenslet rows from the camera's columns, degrees")
    gain_px: float = setting(100.0, minimum=0.0, doc="spot shift per wave per pixel of slope, pixels")
    spot_sigma_px: float = setting(1.5, minimum=0.0)
    spot_peak: float = setting(0.5, minimum=0.0, doc="fraction of full scale")
    background: float = setting(0.02, minimum=0.0, doc="fraction of full scale")
    noise_rms: float = setting(0.002, minimum=0.0, doc="fraction of full scale")
    bit_depth: BitDepth = 12
    min_fill: float = setting(1.0, minimum=0.0, maximum=1.0, doc="illuminated fraction of a valid lenslet")
    fill_samples: int = setting(8, minimum=2)
    magnification: float = setting(1.0, minimum=0.0, doc="camera pixels per optic pixel")
    pupil_shift_px: tuple[float, float] = (0.0, 0.0)
    seed: int = setting(0, minimum=0)
