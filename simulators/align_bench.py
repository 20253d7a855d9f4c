"""The simulated TMA alignment bench: a hexapod, a field stage and the telescope they look through.

Two simulated PI GCS controllers (:class:`~wavestack.simulators.pi_gcs.HexapodSimulator`, on
loopback) and the as-built telescope (:class:`~wavestack.pipeline.telescope.TmaModel` with seeded
as-built errors and the aligned mirror's unknown mount error). :meth:`AlignmentBench.wavefront`
renders what the interferometer sees *now*: the field point the field stage's position selects
(``position / mm_per_deg``, axes 1 and 2 -> theta_x, theta_y) through the pose the hexapod
simulator holds, both read at render time, plus seeded white noise per pixel. The camera fault
switch (:meth:`AlignmentBench.lose_camera`) makes the next renders fail as a lost camera does.

:class:`SurfaceCoupling` puts the wavefront on a station test optic's surface, so that the
station's simulated camera records its fringes, with the reference's tilt set as an operator
sets it (the return spot centred, :func:`~wavestack.pipeline.telescope.centring_tilt`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline.telescope import AsBuiltErrors, HexapodPose, ReferenceTilt, TmaDesign, TmaModel, centring_tilt
from wavestack.simulators.pi_gcs import HexapodSimSettings, HexapodSimulator

__all__ = ["AlignmentBench", "CameraLost", "SurfaceCoupling", "draw_mount"]

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
    host, hexapod_port, field_stage_port : str, int, int
        Where the two controllers listen (default: loopback, free ports).
    """

    def __init__(self, design: TmaDesign, as_built: AsBuiltErrors, mount: HexapodPose, *,
                 hexapod: HexapodSimSettings, field_stage: HexapodSimSettings, mm_per_deg: float,
                 noise_waves: float = 0.0, seed: int = 0, host: str = "127.0.0.1", hexapod_port: int = 0,
                 field_stage_port: int = 0) -> None:
        if len(field_stage.axes) != 2:
            raise ValueError(f"field_stage: expected 2 axes, got {field_stage.axes}")
        self.truth = TmaModel(design, as_built, mount=mount)
        self.hexapod = HexapodSimulator(hexapod, host=host, port=hexapod_port)
        self.field_stage = HexapodSimulator(field_stage, host=host, port=field_stage_port)
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
    wavelength_nm``; :meth:`refresh` sets the heights to ``(wavefront - reference tilt) *
    wavelength_nm / reflection_factor`` (zero outside the pupil) through the surface's own
    ``apply_removal`` (one revision per refresh), so the frames rendered after it show the
    field point and hexapod pose of that moment. The optic's grid must be the TMA's camera grid.

    The reference tilt (``null_tilt``) is what an interferometer operator does at each field
    point before measuring: tip/tilt the reference (or follow the image laterally) until the
    return spot is centred in the alignment view, i.e. null the fringes' tilt
    (:func:`~wavestack.pipeline.telescope.centring_tilt`). A misaligned secondary moves the image by far more than it
    aberrates it: over +-0.3 mm / +-0.03 deg the tilt alone reaches 0.9 waves per pixel on the
    1 mm pixels of the 256 x 128 grid (aliased beyond 0.5), the rest of the map under 0.1
    (docs/alignment.md). The tilt set is returned so that the measurement adds it back: the
    loop sees the whole wavefront, image motion included.

    Parameters
    ----------
    bench : AlignmentBench
    surface : SurfaceState
        The station optic's surface (``devices.bench.optic.surface``).
    wavelength_nm, reflection_factor : float
        As the optic's ``[optic.surface]`` converts heights to waves.
    null_tilt : bool
        Centre the return spot before each measurement (default) or leave the tilt on the fringes.
    """

    def __init__(self, bench: AlignmentBench, surface, wavelength_nm: float,  # noqa: ANN001
                 reflection_factor: float, *, null_tilt: bool = True) -> None:
        if surface is None or tuple(surface.shape) != tuple(bench.truth.design.camera_shape):
            raise ValueError(f"surface: expected the station optic's surface on the TMA grid "
                             f"{bench.truth.design.camera_shape}, got {None if surface is None else surface.shape}")
        self._bench, self._surface, self._null_tilt = bench, surface, bool(null_tilt)
        self._nm_per_wave = float(wavelength_nm) / float(reflection_factor)

    def refresh(self) -> tuple[BenchFrame, ReferenceTilt]:
        """Render the wavefront now, set the reference tilt, put the rest on the surface.

        Returns the frame (its time is the refresh's) and the reference tilt set (zero without
        ``null_tilt``).
        """
        frame = self._bench.wavefront()
        tilt = centring_tilt(frame.waves) if self._null_tilt else ReferenceTilt()
        target = np.nan_to_num(frame.waves - tilt.plane(frame.waves.shape), nan=0.0) * self._nm_per_wave
        self._surface.apply_removal(self._surface.heights_nm() - target)
        return frame, tilt
