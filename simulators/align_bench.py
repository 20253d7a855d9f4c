"""The simulated TMA alignment bench: a hexapod, a field stage and the telescope they look through.

Two simulated PI GCS controllers (:class:`~wavestack.simulators.pi_gcs.HexapodSimulator`, on
loopback) and the as-built telescope (:class:`~wavestack.simulators.tma.TmaModel` with seeded
as-built errors and the aligned mirror's unknown mount error). :meth:`AlignmentBench.wavefront`
renders what the interferometer sees *now*: the field point the field stage's position selects
(``position / mm_per_deg``, axes 1 and 2 -> theta_x, theta_y) through the pose the hexapod
simulator holds, both read at render time, plus seeded white noise per pixel. The camera fault
switch (:meth:`AlignmentBench.lose_camera`) makes the next renders fail as a lost camera does.

This is the model-level bench (wavefront maps, no fringes): the station's interferogram path is
not wired to the TMA yet (docs/alignment.md says what is left).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.pi_gcs import HexapodSimSettings, HexapodSimulator
from wavestack.simulators.tma import AsBuiltErrors, HexapodPose, TmaDesign, TmaModel

__all__ = ["AlignmentBench", "CameraLost", "draw_mount"]


class CameraLost(ConnectionError):
    """The simulated camera stopped delivering frames."""


def draw_mount(decentre_mm: float, despace_mm: float, tilt_deg: float, seed: int) -> HexapodPose:
    """A seeded mount error, uniform in ``+-range`` per dof (X Y decentre, Z despace, U V tilt; W = 0).

    Example
    -------
    >>> pose = draw_mount(0.3, 0.3, 0.03, 1)
    >>> abs(pose.x) <= 0.3 and abs(pose.u) <= 0.03 and pose.w == 0.0
    True
    """
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-decentre_mm, decentre_mm, 2)
    z = rng.uniform(-despace_mm, despace_mm)
    u, v = rng.uniform(-tilt_deg, tilt_deg, 2)
    return HexapodPose(float(x), float(y), float(z), float(u), float(v), 0.0)


@dataclass(frozen=True, eq=False)
class BenchFrame:
    """One rendered wavefront: waves (H, W) NaN outside the pupil, field (deg) and pose it shows, host time ns."""

    waves: NDArray[np.float64]
    field_deg: tuple[float, float]
    pose: HexapodPose
    exposure_ns: int


class AlignmentBench:
    """The simulated bench (module notes); a context manager that starts and stops both simulators.

    Parameters
    ----------
    design : TmaDesign
    as_built : AsBuiltErrors
    mount : HexapodPose
        The aligned mirror's unknown mount error.
    hexapod, field_stage : HexapodSimSettings
        The two controllers (the field stage has two axes).
    mm_per_deg : float
        Field stage travel per degree of field.
    noise_waves : float
        RMS of the white noise added per pixel, waves.
    seed : int
        Seed of the noise.
    """

    def __init__(self, design: TmaDesign, as_built: AsBuiltErrors, mount: HexapodPose, *,
                 hexapod: HexapodSimSettings, field_stage: HexapodSimSettings, mm_per_deg: float,
                 noise_waves: float = 0.0, seed: int = 0) -> None:
        if len(field_stage.axes) != 2:
            raise ValueError(f"field_stage: expected 2 axes, got {field_stage.axes}")
        self.truth = TmaModel(design, as_built, mount=mount)
        self.hexapod = HexapodSimulator(hexapod)
        self.field_stage = HexapodSimulator(field_stage)
        self.mm_per_deg = float(mm_per_deg)
        self._noise = float(noise_waves)
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._lost = 0

    def __enter__(self) -> AlignmentBench:
        self.hexapod.start()
        try:
            self.field_stage.start()
        except BaseException:
            self.hexapod.stop()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.field_stage.stop()
        finally:
            self.hexapod.stop()

    def lose_camera(self, renders: int = 1) -> None:
        """The next ``renders`` calls of :meth:`wavefront` raise :class:`CameraLost`."""
        with self._lock:
            self._lost += int(renders)

    def field_deg(self) -> tuple[float, float]:
        """The field point the stage selects now, deg."""
        pose = self.field_stage.pose
        return (pose.values[0] / self.mm_per_deg, pose.values[1] / self.mm_per_deg)

    def hexapod_pose(self) -> HexapodPose:
        """The hexapod simulator's pose now."""
        pose = self.hexapod.pose
        return HexapodPose(*(pose.get(axis) for axis in ("X", "Y", "Z", "U", "V", "W")))

    def wavefront(self) -> BenchFrame:
        """Render what the interferometer sees now (module notes).

        Raises
        ------
        CameraLost
            While the camera fault is armed.
        """
        with self._lock:
            if self._lost > 0:
                self._lost -= 1
                raise CameraLost("simulated camera lost: no frame")
        exposure = time.time_ns()
        field, pose = self.field_deg(), self.hexapod_pose()
        waves = self.truth.wavefront(field, pose)
        if self._noise > 0:
            with self._lock:
                noise = self._rng.normal(0.0, self._noise, waves.shape)
            waves = waves + noise
        return BenchFrame(waves, field, pose, exposure)


class SurfaceCoupling:
    """Puts the bench's wavefront on a station test optic's surface, so the station's camera sees it.

    The station's simulated interferometer renders its :class:`~wavestack.simulators.optic.TestOptic`
    (zero Zernike figure) plus the optic's surface, ``W = reflection_factor * heights /
    wavelength_nm``; :meth:`refresh` sets the heights to ``wavefront * wavelength_nm /
    reflection_factor`` (zero outside the pupil) through the surface's own
    ``apply_removal`` (one revision per refresh), so the frames rendered after it show the
    field point and hexapod pose of that moment. The optic's grid must be the TMA's camera grid.

    Parameters
    ----------
    bench : AlignmentBench
    surface : SurfaceState
        The station optic's surface (``devices.bench.optic.surface``).
    wavelength_nm, reflection_factor : float
        As the optic's ``[optic.surface]`` converts heights to waves.
    """

    def __init__(self, bench: AlignmentBench, surface, wavelength_nm: float,  # noqa: ANN001
                 reflection_factor: float) -> None:
        if surface is None or tuple(surface.shape) != tuple(bench.truth.design.camera_shape):
            raise ValueError(f"surface: expected the station optic's surface on the TMA grid "
                             f"{bench.truth.design.camera_shape}, got {None if surface is None else surface.shape}")
        self._bench, self._surface = bench, surface
        self._nm_per_wave = float(wavelength_nm) / float(reflection_factor)

    def refresh(self) -> BenchFrame:
        """Render the wavefront now and put it on the surface; returns the frame (its time is the refresh's)."""
        frame = self._bench.wavefront()
        target = np.nan_to_num(frame.waves, nan=0.0) * self._nm_per_wave
        self._surface.apply_removal(self._surface.heights_nm() - target)
        return frame
