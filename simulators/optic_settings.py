"""Settings of the simulated test optic: its wavefront, surface, fringes, levels, noise and camera depth.

:class:`OpticSettings` is what :class:`~wavestack.simulators.optic.TestOptic` is built from; the
meaning of the coefficients and the intensity model are described in
:mod:`wavestack.simulators.optic`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.simulators._checks import check_bit_depth, check_seed, finite_number, nonnegative_number, number_pair
from wavestack.simulators.aperture_shape import ApertureShape
from wavestack.simulators.calibration_ball import BallSettings
from wavestack.simulators.surface_settings import SurfaceSettings, check_figure_sources

BitDepth = Literal[8, 12, 16]


@dataclass(frozen=True)
class ReferenceSettings:
    """The interferometer's reference (transmission flat or sphere, relay optics) and its figure error.

    The error is what every measurement sees besides the part: a wavefront fixed in the camera's
    frame, added to the optic's whatever the part's rotation. It is given in nm of *wavefront*
    (what the interferometer measures; a reference surface in a Fizeau cavity shows twice its
    height), on the current aperture's unit disk (the optic's module notes).

    Attributes
    ----------
    zernike_nm : tuple of float
        Noll-ordered unit-RMS coefficients ``c_1, c_2, ...``, nm of wavefront (may be empty).
    map_file : str or None
        A measured map (``.dat``, ``.datx``, 4D ``.h5``, ``.npy`` in nm) scaled onto the aperture's
        disk as the optic's surface map is (:func:`~wavestack.simulators.surface_sources.measured_surface_nm`).
    map_rms_nm : float or None
        Scale the map to this RMS over the aperture, nm; only with ``map_file``.
    wavelength_nm : float
        Test wavelength, nm (``> 0``): waves = nm / wavelength.

    Raises
    ------
    ValueError
        A field out of range; the message names it.

    Example
    -------
    >>> ReferenceSettings(zernike_nm=(0.0, 0.0, 0.0, 0.0, 12.0)).waves_per_nm == 1 / 632.8
    True
    """

    zernike_nm: tuple[float, ...] = ()
    map_file: str | None = None
    map_rms_nm: float | None = None
    wavelength_nm: float = 632.8

    def __post_init__(self) -> None:
        check_figure_sources(self.zernike_nm, self.map_file, self.map_rms_nm)
        finite_number(self.wavelength_nm, "wavelength_nm", above=0.0)

    @property
    def waves_per_nm(self) -> float:
        """Waves of wavefront per nm of wavefront, ``1 / wavelength_nm``."""
        return 1.0 / self.wavelength_nm


@dataclass(frozen=True)
class OpticSettings:
    """What the test optic looks like and how the interferometer camera sees it.

    Attributes
    ----------
    aperture : ApertureShape
        Initial clear aperture.
    zernike_waves : tuple of float
        Noll-ordered coefficients ``c_1, c_2, ...`` (piston first), unit-RMS normalised over
        the aperture's circumscribing disk (module notes), waves of wavefront; at least one.
    drift_waves_per_s : tuple of float
        Linear drift of each coefficient, waves per second, same length as ``zernike_waves``,
        or empty for none: ``c(t) = zernike_waves + t * drift_waves_per_s``.
    carrier_cycles : (float, float)
        Tilt fringes ``(nx, ny)`` across the frame's width and height (y up); (0, 0) for
        phase shifting.
    background, modulation : float
        ``I = background + modulation cos(...)`` inside the aperture, fractions of full scale,
        ``>= 0``.
    halo : float
        Uniform level outside the aperture, fraction of full scale, ``>= 0``.
    noise_rms : float
        Gaussian read noise, fraction of full scale, ``>= 0``.
    vibration_rms_rad : float
        Piston jitter added to every frame's phase, RMS radians, ``>= 0``.
    vibration_hz : float
        ``> 0``: a sinusoid ``sqrt(2) rms sin(2 pi f t + p0)`` (phase ``p0`` from the seed);
        0: white jitter, a fresh normal draw per frame.
    bit_depth : {8, 12, 16}
        Bits per pixel; frames are uint8 for 8, uint16 otherwise.
    seed : int
        Seed of the noise, the vibration phase and the jitter draws.
    surface : SurfaceSettings or None
        The optic's surface as a height map that polishing can change (its wavefront part adds
        to ``zernike_waves``); None: no surface, the wavefront is the Zernike terms alone.
    reference : ReferenceSettings or None
        The interferometer's reference error, added to every frame in the camera's frame (it does
        not turn with the part); None: a perfect reference.
    ball : BallSettings or None
        A calibration ball at the confocal position (the random ball test): its figure, in the
        current seating, adds to the wavefront (the part's terms are then normally zero).

    Raises
    ------
    ValueError
        If a field is out of range or the drift has another length; the message names it.
    """

    aperture: ApertureShape = ApertureShape()
    zernike_waves: tuple[float, ...] = (0.0, 0.0, 0.0, 0.5, 0.1, -0.2, 0.1, 0.05, 0.03, -0.02, 0.25)
    drift_waves_per_s: tuple[float, ...] = ()
    carrier_cycles: tuple[float, float] = (0.0, 0.0)
    background: float = 0.45
    modulation: float = 0.4
    halo: float = 0.03
    noise_rms: float = 0.005
    vibration_rms_rad: float = 0.0
    vibration_hz: float = 0.0
    bit_depth: BitDepth = 12
    seed: int = 0
    surface: SurfaceSettings | None = None
    reference: ReferenceSettings | None = None
    ball: BallSettings | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.aperture, ApertureShape):
            raise ValueError(f"aperture: expected an ApertureShape, got {type(self.aperture).__name__}")
        if len(self.zernike_waves) < 1:
            raise ValueError("zernike_waves: expected at least one Noll coefficient (piston first)")
        for index, value in enumerate(self.zernike_waves):
            finite_number(value, f"zernike_waves[{index}]")
        if len(self.drift_waves_per_s) not in (0, len(self.zernike_waves)):
            raise ValueError(
                f"drift_waves_per_s: expected {len(self.zernike_waves)} values (one per coefficient) "
                f"or none, got {len(self.drift_waves_per_s)}"
            )
        for index, value in enumerate(self.drift_waves_per_s):
            finite_number(value, f"drift_waves_per_s[{index}]")
        number_pair(self.carrier_cycles, "carrier_cycles")
        for name in ("background", "modulation", "halo", "noise_rms", "vibration_rms_rad", "vibration_hz"):
            nonnegative_number(getattr(self, name), name)
        check_bit_depth(self.bit_depth)
        check_seed(self.seed)
        if self.surface is not None and not isinstance(self.surface, SurfaceSettings):
            raise ValueError(f"surface: expected SurfaceSettings or None, got {type(self.surface).__name__}")
        if self.reference is not None and not isinstance(self.reference, ReferenceSettings):
            raise ValueError(f"reference: expected ReferenceSettings or None, got {type(self.reference).__name__}")
        if self.ball is not None and not isinstance(self.ball, BallSettings):
            raise ValueError(f"ball: expected BallSettings or None, got {type(self.ball).__name__}")

    @property
    def full_scale(self) -> int:
        """Largest count, ``2**bit_depth - 1``."""
        return (1 << self.bit_depth) - 1
