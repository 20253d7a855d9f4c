"""The random ball test's calibration ball: a sphere with its own figure error, re-seated at a random orientation.

The ball's figure is a smooth random field on the unit sphere, a sum of ``terms`` plane waves
``h(x) = sum_k a_k cos(w_k . x + p_k)`` over points ``x`` of the sphere (``|w_k|`` uniform in
``[1, max_frequency]`` radians per radian, directions uniform, phases uniform), scaled to
``figure_nm`` RMS over the whole sphere (estimated once on 20 000 random points, seeded). It is
given in nm of *wavefront* (the interferometer's double pass included).

At the confocal position the interferometer sees a cap of the ball: a pupil point at normalised
radius ``rho`` and angle ``phi`` looks along ``d = (sin(rho a) cos phi, sin(rho a) sin phi,
cos(rho a))``, ``a`` the cap's half angle (the transmission sphere's cone). A seating is a
rotation ``R`` drawn uniformly over SO(3) (:meth:`CalibrationBall.reseat`, seeded); the wavefront
seen is ``h(R d)``. Averaging many seatings, the ball's part tends to its mean over the sphere
(a constant) as ``1 / sqrt(N)``: the principle of the random ball test (Parks, Evans, Shao).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from wavestack.simulators._checks import check_seed, finite_number

__all__ = ["BallSettings", "CalibrationBall"]

_RMS_POINTS = 20_000


@dataclass(frozen=True)
class BallSettings:
    """The calibration ball.

    Attributes
    ----------
    figure_nm : float
        RMS of its figure over the whole sphere, nm of wavefront (``>= 0``).
    cap_half_angle_deg : float
        Half angle of the cap the interferometer sees (the transmission sphere's cone), in (0, 90].
    terms : int
        Plane waves in the random field (``>= 1``).
    max_frequency : float
        Largest spatial frequency, radians of phase per radian on the sphere (``>= 1``).
    seed : int
        Seed of the figure and of the seatings.
    wavelength_nm : float
        Test wavelength, nm: waves = nm / wavelength.
    """

    figure_nm: float = 10.0
    cap_half_angle_deg: float = 30.0
    terms: int = 40
    max_frequency: float = 12.0
    seed: int = 0
    wavelength_nm: float = 632.8

    def __post_init__(self) -> None:
        finite_number(self.figure_nm, "figure_nm", minimum=0.0)
        angle = finite_number(self.cap_half_angle_deg, "cap_half_angle_deg", above=0.0)
        if angle > 90.0:
            raise ValueError(f"cap_half_angle_deg: expected at most 90, got {angle}")
        if isinstance(self.terms, bool) or not isinstance(self.terms, int) or self.terms < 1:
            raise ValueError(f"terms: expected an integer >= 1, got {self.terms!r}")
        finite_number(self.max_frequency, "max_frequency", minimum=1.0)
        check_seed(self.seed)
        finite_number(self.wavelength_nm, "wavelength_nm", above=0.0)


class CalibrationBall:
    """The ball and its current seating (module notes); thread-safe.

    Example
    -------
    >>> ball = CalibrationBall(BallSettings(figure_nm=10.0, seed=1))
    >>> first = ball.cap_nm(np.array([0.0, 0.5]), np.array([0.0, 0.0]))
    >>> ball.reseat(); bool(np.all(first != ball.cap_nm(np.array([0.0, 0.5]), np.array([0.0, 0.0]))))
    True
    """

    def __init__(self, settings: BallSettings) -> None:
        self.settings = settings
        rng = np.random.default_rng(settings.seed)
        directions = rng.standard_normal((settings.terms, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        self._waves = directions * rng.uniform(1.0, settings.max_frequency, (settings.terms, 1))
        self._phases = rng.uniform(0.0, 2.0 * np.pi, settings.terms)
        self._amplitudes = rng.standard_normal(settings.terms)
        points = rng.standard_normal((_RMS_POINTS, 3))
        points /= np.linalg.norm(points, axis=1, keepdims=True)
        spread = float(np.std(self._field(points)))
        self._scale = 0.0 if spread == 0 else settings.figure_nm / spread
        self._rng = rng
        self._lock = threading.Lock()
        self._rotation = Rotation.identity()
        self.seatings = 0

    def _field(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.cos(points @ self._waves.T + self._phases) @ self._amplitudes

    def reseat(self) -> None:
        """Take the ball out and seat it again at a random orientation."""
        with self._lock:
            self._rotation = Rotation.random(random_state=self._rng)
            self.seatings += 1

    def cap_nm(self, u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """The ball's figure seen at pupil points ``(u, v)`` of the unit disk in this seating, nm of wavefront."""
        with self._lock:
            rotation = self._rotation
        angle = np.hypot(u, v) * math.radians(self.settings.cap_half_angle_deg)
        phi = np.arctan2(v, u)
        directions = np.column_stack([np.sin(angle) * np.cos(phi), np.sin(angle) * np.sin(phi), np.cos(angle)])
        return self._scale * self._field(rotation.apply(directions))
