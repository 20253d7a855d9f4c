"""Shack-Hartmann spot frames of the simulated test optic, with the true spot displacements.

A :class:`SpotRenderer` images the wavefront of a :class:`~wavestack.simulators.optic.TestOptic`
through a square or hexagonal lenslet array onto a camera and returns each frame with its ground
truth (:class:`SpotTruth`).

Conventions (those of :mod:`wavestack.pipeline.shack_hartmann`: centroids, slopes and
reconstruction)
----------------------------------------------------------------------------------------------
* Pixel ``(row, col)`` has its centre at ``(col, row)``; positions are ``(col, row)`` pairs;
  physical coordinates are ``x = col``, ``y = -row`` (x right, y up).
* The array has ``rows x cols`` lenslets numbered row-major, ``k = i * cols + j``. Lenslet
  ``(0, 0)`` is centred at ``offset + pitch / 2`` along both axes; row ``i`` runs along the unit
  vector ``r = (cos t, sin t)`` (``t = orientation_deg``, ``(d_col, d_row)``), and rows are
  stacked along ``s = (-sin t, cos t)``: lenslet ``(i, j)`` is centred at
  ``first + pitch (j + h_i) r + q i s`` with ``h_i = 0``, ``q = pitch`` for a square array and
  ``h_i = (i mod 2) / 2``, ``q = pitch sqrt(3) / 2`` for a hexagonal one (odd rows shifted by
  half a pitch). Its subaperture is its cell: the square of side ``pitch`` (turned with the
  array), or the regular hexagon whose edges lie half a pitch from the centre across ``r`` and
  the two directions 60 degrees from it. For an axis-aligned square array, lenslet ``(i, j)``
  covers columns ``offset[0] + [j, j + 1) pitch`` and rows ``offset[1] + [i, i + 1) pitch``.
  The pipeline's ``LensletLattice.array(kind, pitch, renderer.grid_shape, first_centre_px=first,
  orientation_deg=t)`` describes the same lenslets in the same order (written there
  independently).
* The optic's pupil is relayed onto the lenslet array: camera point
  ``p = magnification * q + pupil_shift_px`` for optic pixel point ``q`` (both ``(col, row)``).
* Spot ``k`` is displaced from its lenslet centre by ``gain * <grad W>_k``, where ``W`` is the
  optic's wavefront in waves, the gradient ``(dW/dx, dW/dy)`` is taken per *camera* pixel with
  y up, and ``<.>_k`` is its mean over the illuminated part of the subaperture (the centroid of
  a lenslet's far field is the mean wavefront gradient over its illuminated area). So the column
  displacement is ``+gain dW/dx`` and the row displacement ``-gain dW/dy``.
* ``gain_px`` is the displacement in pixels per unit slope in waves per pixel: for lenslets of
  focal length ``f``, camera pixels ``p`` and wavelength ``lambda`` (one length unit),
  ``gain = f lambda / p**2`` (:meth:`LensletArraySettings.gain_for`). The pipeline's
  ``slopes(measurement, grid.centres(), focal_length_um=f, pixel_um=p)`` followed by
  ``convert_slopes(..., wavefront_unit_um=lambda, length_unit_um=p)`` gives slopes in waves per
  pixel (``displacement / gain``), and
  ``ModalReconstructor.for_circle(grid.centres_xy(), (cx, -cy), R, modes, valid)`` with
  ``(cx, cy, R) = truth.pupil_px`` turns them into the optic's coefficients in waves.

Spots are pixel-integrated Gaussians (``erf`` differences, separable) of peak
``spot_peak * fill`` over a uniform ``background``, rendered into small square patches for all
lenslets at once; Gaussian read noise comes from a pre-drawn pool at a random offset; frames are
rounded and clipped to the bit depth. Lenslets whose subaperture misses the aperture stay dark.

References
----------
.. [1] B. C. Platt and R. Shack, "History and principles of Shack-Hartmann wavefront
   sensing", J. Refract. Surg. 17, S573-S577 (2001).
.. [2] M. R. Teague, "Irradiance moments: their propagation and use for unique retrieval of
   phase", J. Opt. Soc. Am. 72, 1199-1209 (1982) (the far-field centroid is the mean phase
   gradient over the pupil).
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.special
from numpy.typing import NDArray

from wavestack.pipeline import zernike_gradient

from wavestack.simulators._checks import (check_bit_depth, check_image_size, check_seed, finite_number, is_integer,
                                          read_only)
from wavestack.simulators.lenslet_array import LensletArray
from wavestack.simulators.optic import BitDepth, TestOptic

logger = logging.getLogger(__name__)

_NOISE_POOL_EXTRA = 1 << 18  # spare noise samples: the random offset of a frame's noise slice
_PATCH_SIGMAS = 4.0  # spot patches reach this many sigma from the spot centre


@dataclass(frozen=True)
class LensletArraySettings:
    """The lenslet array, the relay from the optic and the Shack-Hartmann camera.

    Attributes
    ----------
    pitch_px : float
        Lenslet pitch on the camera, pixels, ``>= 4``.
    offset_px : (float, float)
        Lenslet (0, 0) is centred at ``offset_px + pitch_px / 2`` along both axes (an
        axis-aligned square array: the top-left corner of its cell), pixels, ``>= -0.5``.
    grid_shape : (int, int) or None
        ``(rows, cols)`` of lenslets; None: the most rows and columns whose cells all lie in
        the frame (columns from the first two rows, then as many rows as hold them all).
    lattice : {"square", "hexagonal"}
        The array's kind (module notes).
    orientation_deg : float
        Angle of the lenslet rows from the camera's columns towards its rows, degrees.
    gain_px : float
        Spot displacement in pixels per wavefront slope of one wave per pixel, ``> 0``
        (``f lambda / p**2``, see :meth:`gain_for`).
    spot_sigma_px : float
        Gaussian spot sigma, pixels, ``> 0``.
    spot_peak : float
        Peak of a fully illuminated lenslet's spot above the background, fraction of full scale.
    background : float
        Uniform level, fraction of full scale.
    noise_rms : float
        Gaussian read noise, fraction of full scale.
    bit_depth : {8, 12, 16}
    min_fill : float
        A lenslet is valid when at least this fraction of its subaperture is illuminated, in
        ``(0, 1]``.
    fill_samples : int
        Sub-samples per axis of each subaperture for its fill and mean gradient (midpoint rule),
        ``>= 2``.
    magnification : float
        Camera pixels per optic pixel of the pupil relay, ``> 0``.
    pupil_shift_px : (float, float)
        ``(col, row)`` on the camera of the optic's pixel (0, 0).
    seed : int
        Seed of the noise.

    Raises
    ------
    ValueError
        If a field is out of range; the message names it.
    """

    pitch_px: float = 25.0
    offset_px: tuple[float, float] = (0.0, 0.0)
    grid_shape: tuple[int, int] | None = None
    lattice: Literal["square", "hexagonal"] = "square"
    orientation_deg: float = 0.0
    gain_px: float = 100.0
    spot_sigma_px: float = 1.5
    spot_peak: float = 0.5
    background: float = 0.02
    noise_rms: float = 0.002
    bit_depth: BitDepth = 12
    min_fill: float = 1.0
    fill_samples: int = 8
    magnification: float = 1.0
    pupil_shift_px: tuple[float, float] = (0.0, 0.0)
    seed: int = 0

    def __post_init__(self) -> None:
        finite_number(self.pitch_px, "pitch_px", minimum=4.0)
        for index, value in enumerate(self.offset_px):
            finite_number(value, f"offset_px[{index}]", minimum=-0.5)
        if len(self.offset_px) != 2 or len(self.pupil_shift_px) != 2:
            raise ValueError("offset_px and pupil_shift_px: expected (col, row) pairs")
        if self.grid_shape is not None:
            if len(self.grid_shape) != 2 or any(
                not is_integer(n) or n < 1 for n in self.grid_shape
            ):
                raise ValueError(f"grid_shape: expected (rows, cols) >= 1 or None, got {self.grid_shape!r}")
        if self.lattice not in ("square", "hexagonal"):
            raise ValueError(f"lattice: expected 'square' or 'hexagonal', got {self.lattice!r}")
        finite_number(self.orientation_deg, "orientation_deg")
        for name in ("gain_px", "spot_sigma_px", "magnification"):
            finite_number(getattr(self, name), name, above=0.0)
        for name in ("spot_peak", "background", "noise_rms"):
            finite_number(getattr(self, name), name, minimum=0.0)
        if not 0.0 < finite_number(self.min_fill, "min_fill") <= 1.0:
            raise ValueError(f"min_fill: expected a fraction in (0, 1], got {self.min_fill!r}")
        if isinstance(self.fill_samples, bool) or not isinstance(self.fill_samples, int) or self.fill_samples < 2:
            raise ValueError(f"fill_samples: expected an integer >= 2, got {self.fill_samples!r}")
        for index, value in enumerate(self.pupil_shift_px):
            finite_number(value, f"pupil_shift_px[{index}]")
        check_bit_depth(self.bit_depth)
        check_seed(self.seed)

    @staticmethod
    def gain_for(focal_length_um: float, pixel_um: float, wavelength_um: float) -> float:
        """``gain_px = f lambda / p**2`` for a lenslet focal length, camera pixel and wavelength.

        Parameters
        ----------
        focal_length_um, pixel_um, wavelength_um : float
            Micrometres, each ``> 0``.

        Returns
        -------
        float
            Pixels of displacement per wave-per-pixel of slope.
        """
        focal = finite_number(focal_length_um, "focal_length_um", above=0.0)
        pixel = finite_number(pixel_um, "pixel_um", above=0.0)
        wavelength = finite_number(wavelength_um, "wavelength_um", above=0.0)
        return focal * wavelength / pixel**2


@dataclass(frozen=True, eq=False)
class SpotTruth:
    """The ground truth behind one spot frame. Per-lenslet arrays are row-major, length L.

    Attributes
    ----------
    time_s : float
        Seconds.
    modes : tuple of (int, int)
        Noll-ordered ``(n, m)`` of the coefficients.
    coefficients_waves : ndarray, shape (J,)
        The optic's coefficients at ``time_s`` (unit RMS over the optic's disk), waves.
    pupil_px : (float, float, float)
        That disk on this camera: centre column, centre row, radius, pixels.
    grid_shape : (int, int)
        ``(rows, cols)`` of lenslets.
    centres_px : ndarray, shape (L, 2)
        Lenslet centres ``(col, row)``, pixels.
    slopes_waves_per_px : ndarray, shape (L, 2)
        Mean ``(dW/dx, dW/dy)`` over the illuminated subaperture (x right, y up), waves per
        camera pixel; 0 for dark lenslets.
    displacements_px : ndarray, shape (L, 2)
        Spot displacement ``(d_col, d_row) = gain (dW/dx, -dW/dy)``, pixels.
    positions_px : ndarray, shape (L, 2)
        ``centres_px + displacements_px``: where the spot centres are.
    fill : ndarray, shape (L,)
        Illuminated fraction of each subaperture (sub-sampled).
    valid : ndarray of bool, shape (L,)
        ``fill >= min_fill``.
    aperture_revision : int
        The optic's aperture revision the frame was rendered with.
    """

    time_s: float
    modes: tuple[tuple[int, int], ...]
    coefficients_waves: NDArray[np.float64]
    pupil_px: tuple[float, float, float]
    grid_shape: tuple[int, int]
    centres_px: NDArray[np.float64]
    slopes_waves_per_px: NDArray[np.float64]
    displacements_px: NDArray[np.float64]
    positions_px: NDArray[np.float64]
    fill: NDArray[np.float64]
    valid: NDArray[np.bool_]
    aperture_revision: int


@dataclass(frozen=True, eq=False)
class _Subapertures:
    """Per-aperture precomputation: fill and mean-gradient operators of every lenslet."""

    revision: int
    pupil: tuple[float, float, float]
    fill: NDArray[np.float64]  # (L,)
    valid: NDArray[np.bool_]  # (L,)
    grad_x: NDArray[np.float64]  # (L, J): mean dZ/dx per camera pixel
    grad_y: NDArray[np.float64]  # (L, J): mean dZ/dy (y up) per camera pixel


class SpotRenderer:
    """Shack-Hartmann spot frames of a test optic.

    Parameters
    ----------
    optic : TestOptic
        The optic; its drift and aperture changes show in the frames (vibration, a piston,
        does not).
    lenslets : LensletArraySettings
    height, width : int
        Camera frame size, pixels.

    Raises
    ------
    ValueError
        If the lenslet grid does not fit in the frame or an argument is invalid.
    """

    def __init__(self, optic: TestOptic, lenslets: LensletArraySettings, height: int, width: int) -> None:
        if not isinstance(optic, TestOptic):
            raise ValueError(f"optic: expected a TestOptic, got {type(optic).__name__}")
        if not isinstance(lenslets, LensletArraySettings):
            raise ValueError(f"lenslets: expected LensletArraySettings, got {type(lenslets).__name__}")
        check_image_size(height, width, 8)
        self._optic = optic
        self._lenslets = lenslets
        self._size = (int(height), int(width))
        self._array = LensletArray(lenslets.pitch_px, lenslets.offset_px, lenslets.lattice, lenslets.orientation_deg)
        self._grid_shape = self._array.shape_in(self._size, lenslets.grid_shape)
        self._centres = read_only(self._array.centres(self._grid_shape))
        self._patch = 2 * math.ceil(_PATCH_SIGMAS * lenslets.spot_sigma_px) + 1
        if self._patch > min(self._size):
            raise ValueError(f"spot_sigma_px: spots of {self._patch} px do not fit in the frame")
        self._full_scale = (1 << lenslets.bit_depth) - 1
        self._lock = threading.Lock()
        self._rng = np.random.default_rng(lenslets.seed)
        self._noise = None
        if lenslets.noise_rms > 0:
            pool = self._rng.standard_normal(height * width + _NOISE_POOL_EXTRA, dtype=np.float32)
            pool *= np.float32(lenslets.noise_rms * self._full_scale)
            self._noise = read_only(pool)
        self._cache: _Subapertures | None = None

    @property
    def grid_shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of lenslets."""
        return self._grid_shape

    @property
    def optic(self) -> TestOptic:
        """The optic the spots show (shared: its aperture changes reach the next frame)."""
        return self._optic

    @property
    def lenslets(self) -> LensletArraySettings:
        """The lenslet array settings."""
        return self._lenslets

    @property
    def centres_px(self) -> NDArray[np.float64]:
        """Lenslet centres ``(col, row)``, shape (L, 2), pixels, read-only."""
        return self._centres

    def _subapertures(self) -> _Subapertures:
        """The per-aperture operators, recomputed when the optic's aperture has changed."""
        with self._lock:
            if self._cache is None or self._cache.revision != self._optic.aperture_revision:
                self._cache = self._build()
            return self._cache

    def _build(self) -> _Subapertures:
        settings = self._lenslets
        optic = self._optic
        state = optic.truth(0.0)  # aperture, revision and disk of one consistent rendering
        aperture, (cx, cy, radius), revision = state.aperture, state.pupil_px, state.aperture_revision
        nodes = self._array.cell_nodes(settings.fill_samples)  # (Q, 2) midpoint nodes of one cell
        cols = self._centres[:, 0, None] + nodes[None, :, 0]
        rows = self._centres[:, 1, None] + nodes[None, :, 1]  # (L, Q) camera points
        shift_c, shift_r = settings.pupil_shift_px
        optic_cols = (cols - shift_c) / settings.magnification
        optic_rows = (rows - shift_r) / settings.magnification
        inside = aperture.contains(optic_cols, optic_rows)  # (L, Q)
        count = inside.sum(axis=1)
        fill = count / len(nodes)
        lenslet, _ = np.nonzero(inside)
        u = (optic_cols[inside] - cx) / radius
        v = (cy - optic_rows[inside]) / radius
        grad_u, grad_v = zernike_gradient(optic.modes, u, v)
        sums = np.zeros((2, len(self._centres), len(optic.modes)))
        np.add.at(sums[0], lenslet, grad_u)
        np.add.at(sums[1], lenslet, grad_v)
        per_camera_px = 1.0 / (radius * settings.magnification)  # d/du -> d/dx on the camera
        scale = np.divide(per_camera_px, count, out=np.zeros(count.shape), where=count > 0)[:, None]
        camera_pupil = (cx * settings.magnification + shift_c, cy * settings.magnification + shift_r,
                        radius * settings.magnification)
        logger.debug("spot renderer: %d of %d lenslets lit for aperture revision %d",
                     int(np.count_nonzero(count)), count.size, revision)
        return _Subapertures(
            revision=revision,
            pupil=camera_pupil,
            fill=read_only(fill),
            valid=read_only(fill >= settings.min_fill - 1e-12),
            grad_x=read_only(sums[0] * scale),
            grad_y=read_only(sums[1] * scale),
        )

    def spot_frame(self, time_s: float) -> tuple[NDArray, SpotTruth]:
        """Render one spot frame.

        Parameters
        ----------
        time_s : float
            Seconds (the optic's drift depends on it).

        Returns
        -------
        frame : ndarray of uint8 (8 bits) or uint16, shape (height, width)
        truth : SpotTruth
        """
        t = finite_number(time_s, "time_s")
        settings = self._lenslets
        geometry = self._subapertures()
        coefficients = self._optic.coefficients(t)
        slopes = np.column_stack([geometry.grad_x @ coefficients, geometry.grad_y @ coefficients])
        displacements = settings.gain_px * slopes * np.array([1.0, -1.0])
        positions = self._centres + displacements
        frame = np.full(self._size, np.float32(settings.background * self._full_scale), dtype=np.float32)
        self._draw_spots(frame, positions, geometry.fill)
        with self._lock:
            start = 0 if self._noise is None else int(self._rng.integers(0, _NOISE_POOL_EXTRA + 1))
        if self._noise is not None:
            frame += self._noise[start : start + frame.size].reshape(frame.shape)
        np.clip(frame, 0.0, self._full_scale, out=frame)
        np.rint(frame, out=frame)
        image = frame.astype(np.uint8 if settings.bit_depth == 8 else np.uint16)
        truth = SpotTruth(
            time_s=t,
            modes=self._optic.modes,
            coefficients_waves=coefficients,
            pupil_px=geometry.pupil,
            grid_shape=self._grid_shape,
            centres_px=self._centres,
            slopes_waves_per_px=read_only(slopes),
            displacements_px=read_only(displacements),
            positions_px=read_only(positions),
            fill=geometry.fill,
            valid=geometry.valid,
            aperture_revision=geometry.revision,
        )
        return image, truth

    def _draw_spots(self, frame: NDArray[np.float32], positions: NDArray[np.float64], fill: NDArray) -> None:
        """Add pixel-integrated Gaussian spots of the lit lenslets into ``frame``, all at once."""
        lit = fill > 0
        if not np.any(lit):
            return
        sigma = self._lenslets.spot_sigma_px
        patch = self._patch
        height, width = self._size
        where = positions[lit]
        # flux of a Gaussian of peak A is 2 pi sigma^2 A; a partly lit lenslet gets its share
        flux = (2.0 * np.pi * sigma**2 * self._lenslets.spot_peak * self._full_scale) * fill[lit]
        first_col = np.clip(np.rint(where[:, 0]).astype(np.intp) - patch // 2, 0, width - patch)
        first_row = np.clip(np.rint(where[:, 1]).astype(np.intp) - patch // 2, 0, height - patch)
        edges = np.arange(patch + 1) - 0.5
        scale = 1.0 / (sigma * math.sqrt(2.0))

        def profile(centre: NDArray[np.float64], first: NDArray[np.intp]) -> NDArray[np.float64]:
            """Fraction of a unit 1-D Gaussian over each pixel of the patch, shape (n, patch)."""
            cdf = scipy.special.erf((first[:, None] + edges[None, :] - centre[:, None]) * scale)
            return 0.5 * np.diff(cdf, axis=1)

        values = (flux[:, None, None] * profile(where[:, 1], first_row)[:, :, None]
                  * profile(where[:, 0], first_col)[:, None, :])
        index = ((first_row[:, None, None] + np.arange(patch)[None, :, None]) * width
                 + first_col[:, None, None] + np.arange(patch)[None, None, :])
        spots = np.bincount(index.ravel(), weights=values.ravel(), minlength=height * width)
        frame += spots.reshape(height, width).astype(np.float32)

