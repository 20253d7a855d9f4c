"""The simulated test optic: a surface with known Zernike coefficients, seen as interferograms.

A :class:`TestOptic` holds a wavefront ``W`` (waves) on an aperture of a ``height x width``
camera and renders the interferograms a phase-shifting or carrier-fringe interferometer would
record of it, returning with every frame the ground truth (:class:`OpticTruth`) a test compares
the pipeline's answer with. The aperture (:mod:`~wavestack.simulators.aperture_shape`) and the
settings (:mod:`~wavestack.simulators.optic_settings`) have modules of their own; their public
names are re-exported here.

Coordinates
-----------
Pixel ``(row, col)`` has its centre at the integer point ``(col, row)``. Aperture geometry
(:class:`ApertureShape`) is given as ``(col, row)`` pairs in pixels (rows grow downward).
Rotations are counter-clockwise as the image is displayed, i.e. from ``+col`` towards ``-row``.

The unit disk (what the coefficients mean)
------------------------------------------
The coefficients are Noll-ordered (``j = 1, 2, ...``; :func:`~wavestack.pipeline.mode_list`
``("noll", J)``), unit-RMS circle Zernike polynomials (Noll 1976) over the unit disk that
circumscribes the aperture:

* centre ``(cx, cy)`` (a column and a row) and radius ``R`` in pixels: the minimum enclosing
  circle of the *centres of the valid pixels* of the rasterised mask, exactly
  ``Aperture.from_mask(mask).enclosing_circle()`` -- the pupil ``build_fitter(mask)`` uses by
  default. It is reported as ``OpticTruth.pupil_px`` and can be passed as
  ``build_fitter(..., pupil=truth.pupil_px)`` when the fitted aperture is a detected one;
* ``u = (col - cx) / R`` (right) and ``v = (cy - row) / R`` (up), and
  ``W(col, row) = sum_j c_j Z_j(u, v)`` in waves of wavefront, with ``Z_j`` as
  :func:`~wavestack.pipeline.zernike_basis` evaluates them ("rms" normalisation).

The coefficients belong to the current aperture's disk: :meth:`TestOptic.set_aperture` puts the
same coefficients on the new aperture's disk (as when another optic, or a pupil relayed at
another size, is put in front of the camera), so the truth stays ``zernike_waves`` (plus drift).

Intensity model
---------------
Inside the aperture (sign convention of :mod:`wavestack.pipeline.phase.psi`, ``delta`` the phase
shift)::

    I = background + modulation * cos(2 pi W + carrier + delta + vibration)

with ``carrier = 2 pi (nx * col / width - ny * row / height)`` for ``carrier_cycles = (nx, ny)``
(x right, y up: the ``2 pi (fx x + fy y)`` of :mod:`wavestack.pipeline.phase.carrier` with
``fx = nx / width``, ``fy = ny / height``; with ``nx > 0`` ``carrier_phase(sign=+1)`` returns
``+2 pi W``). Outside the aperture there are no fringes, only a dim uniform halo
(``I = halo``). All levels are fractions of full scale ``2**bit_depth - 1``; Gaussian read
noise of ``noise_rms`` is added, then the frame is rounded to the nearest count and clipped to
``[0, full scale]`` (uint8 for 8 bits, uint16 otherwise).

Surface
-------
With ``settings.surface`` set, the optic also owns a height map, :attr:`TestOptic.surface` (a
:class:`~wavestack.simulators.surface.SurfaceState` built from
:class:`~wavestack.simulators.surface_settings.SurfaceSettings` on the initial aperture's disk,
covering the whole frame). The wavefront rendered is then ``W + reflection_factor * heights /
wavelength_nm``, re-made whenever the surface's revision changes
(:mod:`~wavestack.simulators.optic_surface`). The surface belongs to the optic: a new aperture
shows another part of the same heights. Without a surface everything is as before.

Reference and rotation
----------------------
With ``settings.reference`` the interferometer's reference carries a figure error
(:class:`~wavestack.simulators.optic_settings.ReferenceSettings`), added to every frame on the
aperture's disk in the camera's frame. :meth:`TestOptic.rotate_part` turns the part's Zernike
figure on its mount about the disk's centre (a rotary mount centred on the pupil); the reference
does not turn. With ``settings.ball`` a calibration ball sits at the confocal position
(:mod:`~wavestack.simulators.calibration_ball`); :meth:`TestOptic.reseat_ball` turns it to a random
orientation. The truth keeps part and reference apart: ``OpticTruth.coefficients_waves`` are the part's own
(unturned) terms, ``reference_waves`` the reference's map, ``wavefront_waves`` their sum as seen.

Speed. The wavefront is linear in time, ``W(t) = B (c + t d) = W0 + t D`` with ``B`` the basis
on the aperture pixels, so the two products ``B c`` and ``B d`` are made once per aperture (the
basis is evaluated in blocks and not kept) and a frame costs a few float32 passes: phase,
``cos``, scale and offset, noise from a pre-drawn pool at a random offset, rounding.

References
----------
.. [1] R. J. Noll, "Zernike polynomials and atmospheric turbulence", J. Opt. Soc. Am. 66,
   207-211 (1976).
.. [2] D. Malacara (ed.), Optical Shop Testing, 3rd ed., Wiley (2007), ch. 14 (phase-shifting
   interferometry: ``I = a + b cos(phi + delta)``).
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import mode_list
from wavestack.simulators._checks import check_image_size, finite_number, read_only
from wavestack.simulators.aperture_shape import ApertureKind, ApertureShape
from wavestack.simulators.calibration_ball import BallSettings, CalibrationBall
from wavestack.simulators.optic_rendering import Rendering, prepare_rendering
from wavestack.simulators.optic_settings import BitDepth, OpticSettings, ReferenceSettings
from wavestack.simulators.optic_surface import SurfacePhase, SurfaceView
from wavestack.simulators.optic_truth import FrameFacts, OpticTruth
from wavestack.simulators.surface import SurfaceState
from wavestack.simulators.surface_sources import initial_heights_nm

__all__ = ["ApertureKind", "ApertureShape", "BallSettings", "BitDepth", "FrameFacts", "OpticSettings", "OpticTruth",
           "ReferenceSettings", "TestOptic"]

logger = logging.getLogger(__name__)

_NOISE_POOL_EXTRA = 1 << 18  # spare noise samples: the random offset of a frame's noise slice


class TestOptic:
    """A test optic with a known, optionally drifting, wavefront, rendered as interferograms.

    Parameters
    ----------
    settings : OpticSettings
    height, width : int
        Camera frame size, pixels (each ``>= 2``).

    Raises
    ------
    ValueError
        If the size is invalid or the aperture covers no pixel of the frame; an
        :class:`~wavestack.pipeline.InputError` naming the surface's map file if it cannot be read.

    Notes
    -----
    Deterministic: two optics with the same settings, size and call sequence render identical
    frames. Thread-safe: frames may be rendered from a camera thread while another thread
    changes the aperture or polishes the surface (a frame uses one aperture and one surface
    revision throughout).
    """

    __test__ = False  # a library class, not a pytest test class, despite its name

    def __init__(self, settings: OpticSettings, height: int, width: int) -> None:
        if not isinstance(settings, OpticSettings):
            raise ValueError(f"settings: expected OpticSettings, got {type(settings).__name__}")
        check_image_size(height, width, 2)
        self._settings = settings
        self._size = (int(height), int(width))
        self._modes = tuple(mode_list("noll", len(settings.zernike_waves)))
        self._coefficients = np.asarray(settings.zernike_waves, dtype=np.float64)
        self._drift = (np.asarray(settings.drift_waves_per_s, dtype=np.float64)
                       if any(settings.drift_waves_per_s) else None)
        self._lock = threading.Lock()  # guards the generator and the swap of the rendering
        self._aperture_lock = threading.Lock()  # serialises aperture changes
        self._rng = np.random.default_rng(settings.seed)
        self._vibration_phase = float(self._rng.uniform(0.0, 2.0 * np.pi))
        pixels = self._size[0] * self._size[1]
        self._noise = None
        if settings.noise_rms > 0:
            pool = self._rng.standard_normal(pixels + _NOISE_POOL_EXTRA, dtype=np.float32)
            pool *= np.float32(settings.noise_rms * settings.full_scale)
            self._noise = read_only(pool)
        self._surface: SurfacePhase | None = None
        if settings.surface is not None:
            heights = initial_heights_nm(settings.surface, settings.aperture.mask(height, width))
            state = SurfaceState(heights, settings.surface.pixel_mm)
            self._surface = SurfacePhase(state, settings.surface.waves_per_nm)
        self._rotation_deg = 0.0
        self._ball = None if settings.ball is None else CalibrationBall(settings.ball)
        self._rendering = self._prepare(settings.aperture, revision=0)

    # ----------------------------------------------------------------------------- properties

    @property
    def settings(self) -> OpticSettings:
        """The settings the optic was built with (``aperture`` is the initial one)."""
        return self._settings

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)`` of the frames, pixels."""
        return self._size

    @property
    def modes(self) -> tuple[tuple[int, int], ...]:
        """``(n, m)`` of the coefficients, Noll order from ``j = 1``."""
        return self._modes

    @property
    def aperture(self) -> ApertureShape:
        """The aperture in force."""
        return self._rendering.shape

    @property
    def aperture_revision(self) -> int:
        """0 for the initial aperture, +1 per :meth:`set_aperture` or :meth:`rotate_part`."""
        return self._rendering.revision

    @property
    def pupil_px(self) -> tuple[float, float, float]:
        """The unit disk ``(cx, cy, R)`` of the current aperture: column, row, radius, pixels."""
        return self._rendering.pupil

    @property
    def surface(self) -> SurfaceState | None:
        """The optic's surface height map (None when ``settings.surface`` is None)."""
        return None if self._surface is None else self._surface.state

    @property
    def mask(self) -> NDArray[np.bool_]:
        """The rasterised current aperture, shape (height, width), read-only."""
        return self._rendering.mask

    @property
    def part_rotation_deg(self) -> float:
        """The part's rotation on its mount, degrees counter-clockwise as displayed (0 at start)."""
        return self._rendering.rotation_deg

    def coefficients(self, time_s: float) -> NDArray[np.float64]:
        """``c(t) = zernike_waves + t drift_waves_per_s``, shape (J,), waves."""
        t = finite_number(time_s, "time_s")
        values = self._coefficients if self._drift is None else self._coefficients + t * self._drift
        return read_only(values.copy())

    # ----------------------------------------------------------------------------- aperture

    def set_aperture(self, shape: ApertureShape) -> None:
        """Change the aperture mid-run; the next frame is rendered on the new one.

        The basis products are recomputed on the new aperture and its own circumscribing disk;
        the coefficients keep their values (module notes); the surface stays as it is.

        Parameters
        ----------
        shape : ApertureShape

        Raises
        ------
        ValueError
            If ``shape`` is not an ApertureShape or covers no pixel of the frame.
        """
        if not isinstance(shape, ApertureShape):
            raise ValueError(f"shape: expected an ApertureShape, got {type(shape).__name__}")
        with self._aperture_lock:
            rendering = self._prepare(shape, revision=self._rendering.revision + 1)
            with self._lock:
                self._rendering = rendering
        logger.info("test optic aperture changed to %s (revision %d)", shape.kind, rendering.revision)

    def reseat_ball(self) -> None:
        """Re-seat the calibration ball at a random orientation (next frame on); ValueError without a ball."""
        if self._ball is None:
            raise ValueError("reseat_ball: the optic has no calibration ball (settings.ball)")
        with self._aperture_lock:
            self._ball.reseat()
            rendering = self._prepare(self._rendering.shape, revision=self._rendering.revision + 1)
            with self._lock:
                self._rendering = rendering

    def _prepare(self, shape: ApertureShape, revision: int) -> Rendering:
        return prepare_rendering(self._settings, self._size, shape, revision, modes=self._modes,
                                 coefficients=self._coefficients, drift=self._drift, rotation_deg=self._rotation_deg,
                                 with_surface=self._surface is not None, ball=self._ball)

    def rotate_part(self, angle_deg: float) -> None:
        """Turn the part on its mount to ``angle_deg`` (absolute, counter-clockwise as displayed).

        The part's Zernike figure (and its drift) turns about the centre of the aperture's unit
        disk; the reference's error stays fixed in the camera's frame; the next frame is rendered
        with the new angle (the rendering's revision grows by one, as for a new aperture).

        Raises
        ------
        ValueError
            A non-finite angle, or an optic with a surface map (a polished height map is not
            turned: the simulator does not resample it).
        """
        angle = finite_number(angle_deg, "angle_deg")
        if self._surface is not None:
            raise ValueError("rotate_part: the optic has a surface map, which the simulator does not turn")
        with self._aperture_lock:
            self._rotation_deg = angle
            rendering = self._prepare(self._rendering.shape, revision=self._rendering.revision + 1)
            with self._lock:
                self._rendering = rendering
        logger.info("test optic part turned to %.4f deg (revision %d)", angle, rendering.revision)

    # ----------------------------------------------------------------------------- frames

    def truth(self, time_s: float) -> OpticTruth:
        """The optic's wavefront at ``time_s`` (no frame: no phase shift, no vibration).

        Parameters
        ----------
        time_s : float
            Seconds.

        Returns
        -------
        OpticTruth
        """
        t = finite_number(time_s, "time_s")
        rendering = self._rendering
        return self._truth(rendering, self._surface_view(rendering), t, 0.0, 0.0, (0.0, 0.0))

    def wavefront(self, time_s: float, step: int = 1) -> NDArray[np.float64]:
        """The optic's wavefront ``W(t)`` on every ``step``-th row and column, waves (NaN outside the aperture).

        The map of :meth:`truth` sliced ``[::step, ::step]``, made on that grid only: a fit of a
        decimated map (the station's truth check) needs no full-frame temporaries.

        Parameters
        ----------
        time_s : float
            Seconds.
        step : int
            Rows and columns kept, every ``step``-th from 0 (``>= 1``).

        Returns
        -------
        ndarray of float64, shape (ceil(height / step), ceil(width / step))

        Example
        -------
        >>> disk = ApertureShape(centre_px=(32.0, 32.0), radius_px=28.0)
        >>> optic = TestOptic(OpticSettings(zernike_waves=(0.0, 0.0, 0.0, 0.2), aperture=disk), 64, 64)
        >>> np.array_equal(optic.wavefront(1.0, 2), optic.truth(1.0).wavefront_waves[::2, ::2], equal_nan=True)
        True
        """
        t = finite_number(time_s, "time_s")
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1:
            raise ValueError(f"step: expected an integer >= 1, got {step!r}")
        rendering = self._rendering
        return self._wavefront_at(rendering, self._surface_view(rendering), t, int(step))

    def interferogram(self, time_s: float, phase_shift_rad: float = 0.0) -> tuple[NDArray, OpticTruth]:
        """Render one interferogram.

        Parameters
        ----------
        time_s : float
            Seconds (drift and sinusoidal vibration depend on it).
        phase_shift_rad : float
            Reference phase ``delta`` added to the phase, radians (``I = A + B cos(phi + delta)``).

        Returns
        -------
        frame : ndarray of uint8 (8 bits) or uint16, shape (height, width)
        truth : OpticTruth
            With the shift and vibration applied to this frame.
        """
        frame, rendering, view, facts = self._render(time_s, phase_shift_rad)
        return frame, self._truth(rendering, view, facts.time_s, facts.phase_shift_rad, facts.vibration_rad,
                                  facts.carrier_cycles)

    def frame(self, time_s: float, phase_shift_rad: float = 0.0) -> tuple[NDArray, FrameFacts]:
        """:meth:`interferogram`'s frame (the same for the same call sequence) without the truth's map.

        For a camera rendering 30 frames/s that keeps only what the map is re-made from: the map is
        a full-frame float64 array per frame. Returns the frame and its :class:`FrameFacts`.

        Example
        -------
        >>> disk = ApertureShape(centre_px=(32.0, 32.0), radius_px=28.0)
        >>> optic = TestOptic(OpticSettings(zernike_waves=(0.0, 0.0, 0.0, 0.2), aperture=disk), 64, 64)
        >>> pixels, facts = optic.frame(0.5, np.pi / 2)
        >>> pixels.shape, facts.phase_shift_rad == np.pi / 2, facts.aperture_revision
        ((64, 64), True, 0)
        """
        frame, _, _, facts = self._render(time_s, phase_shift_rad)
        return frame, facts

    def _render(self, time_s: float, phase_shift_rad: float
                ) -> tuple[NDArray, Rendering, SurfaceView | None, FrameFacts]:
        t = finite_number(time_s, "time_s")
        shift = finite_number(phase_shift_rad, "phase_shift_rad")
        settings = self._settings
        with self._lock:
            rendering = self._rendering
            jitter = 0.0
            if settings.vibration_rms_rad > 0 and settings.vibration_hz == 0:
                jitter = float(self._rng.standard_normal()) * settings.vibration_rms_rad
            start = 0 if self._noise is None else int(self._rng.integers(0, _NOISE_POOL_EXTRA + 1))
        view = self._surface_view(rendering)
        vibration = jitter
        if settings.vibration_rms_rad > 0 and settings.vibration_hz > 0:
            vibration = math.sqrt(2.0) * settings.vibration_rms_rad * math.sin(
                2.0 * math.pi * settings.vibration_hz * t + self._vibration_phase
            )
        phase = rendering.phase if view is None else view.phase
        if rendering.phase_drift is None:
            values = phase + np.float32(shift + vibration)
        else:  # one float32 temporary: the drift term, then the phase and the offset added in place
            values = rendering.phase_drift * np.float32(t)
            values += phase
            values += np.float32(shift + vibration)
        np.cos(values, out=values)
        values *= rendering.amplitude
        values += rendering.offset
        if self._noise is not None:
            values += self._noise[start : start + values.size].reshape(values.shape)
        np.clip(values, 0.0, settings.full_scale, out=values)
        np.rint(values, out=values)
        frame = values.astype(np.uint8 if settings.bit_depth == 8 else np.uint16)
        del values
        facts = FrameFacts(t, shift, vibration, (float(settings.carrier_cycles[0]), float(settings.carrier_cycles[1])),
                           rendering.revision, None if view is None else view.surface_revision)
        return frame, rendering, view, facts

    def _surface_view(self, rendering: Rendering) -> SurfaceView | None:
        """The phase and wavefront with the current surface on ``rendering``'s aperture (None: no surface)."""
        if self._surface is None:
            return None
        assert rendering.index is not None and rendering.base_phase is not None  # made with the surface
        return self._surface.view(rendering.revision, rendering.index, rendering.base_phase, rendering.phase,
                                  rendering.wavefront)

    def _truth(
        self, rendering: Rendering, view: SurfaceView | None, t: float, shift: float, vibration: float,
        carrier: tuple[float, float],
    ) -> OpticTruth:
        wavefront = self._wavefront_at(rendering, view, t, 1)
        return OpticTruth(
            time_s=t,
            modes=self._modes,
            coefficients_waves=self.coefficients(t),
            pupil_px=rendering.pupil,
            wavefront_waves=wavefront,
            mask=rendering.mask,
            aperture=rendering.shape,
            aperture_revision=rendering.revision,
            phase_shift_rad=shift,
            vibration_rad=vibration,
            carrier_cycles=(float(carrier[0]), float(carrier[1])),
            surface_revision=None if view is None else view.surface_revision,
            surface_nm=None if view is None else view.heights_nm,
            rotation_deg=rendering.rotation_deg,
            reference_waves=rendering.reference,
        )

    @staticmethod
    def _wavefront_at(rendering: Rendering, view: SurfaceView | None, t: float, step: int) -> NDArray[np.float64]:
        """``W0 + t D`` (with the surface's part) on every ``step``-th row and column, read-only."""
        wavefront = rendering.wavefront if view is None else view.wavefront  # shared, read-only
        drift = rendering.wavefront_drift
        if step > 1:
            wavefront = wavefront[::step, ::step]
            drift = None if drift is None else drift[::step, ::step]
        if drift is None or t == 0.0:
            return wavefront if step == 1 else read_only(wavefront.copy())
        values = drift * t  # the one array made, of the grid's size; the map is added in place
        values += wavefront
        return read_only(values)
