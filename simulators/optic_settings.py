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
from wavestack.simulators.surface_settings import SurfaceSettings

BitDepth = Literal[8, 12, 16]


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

    @property
    def full_scale(self) -> int:
        """Largest count, ``2**bit_depth - 1``."""
        return (1 << self.bit_depth) - 1
