"""The ground truth behind a frame of the simulated test optic (:class:`OpticTruth`).

:class:`~wavestack.simulators.optic.TestOptic` returns one with every frame; tests compare the
pipeline's answer with it. The meaning of the coefficients, the disk and the surface are described
in :mod:`wavestack.simulators.optic`, which re-exports this name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.aperture_shape import ApertureShape

__all__ = ["FrameFacts", "OpticTruth"]


@dataclass(frozen=True, eq=False)
class OpticTruth:
    """The ground truth behind one frame (or one instant, from :meth:`TestOptic.truth`).

    Attributes
    ----------
    time_s : float
        Time the frame shows, seconds.
    modes : tuple of (int, int)
        ``(n, m)`` of each coefficient, Noll order from ``j = 1``.
    coefficients_waves : ndarray, shape (J,)
        ``c(t)``, unit-RMS Zernike coefficients over the disk ``pupil_px``, waves (read-only): the
        part's own, unturned by ``rotation_deg``.
    pupil_px : (float, float, float)
        The unit disk ``(cx, cy, R)``: centre column, centre row, radius, pixels (module notes).
    wavefront_waves : ndarray, shape (height, width)
        ``W`` in waves (with the surface's part, if any), NaN outside the aperture; no carrier,
        shift or vibration (read-only).
    mask : ndarray of bool, shape (height, width)
        The rasterised aperture (read-only).
    aperture : ApertureShape
        The aperture in force.
    aperture_revision : int
        0 for the initial aperture, +1 per :meth:`TestOptic.set_aperture` or :meth:`TestOptic.rotate_part`.
    phase_shift_rad : float
        The ``delta`` applied to the frame (0 for :meth:`TestOptic.truth`).
    vibration_rad : float
        The piston jitter applied to the frame (0 for :meth:`TestOptic.truth`).
    carrier_cycles : (float, float)
        The carrier ``(nx, ny)`` of the frame, fringes across width and height.
    surface_revision : int or None
        The surface's revision rendered (None: an optic without a surface).
    surface_nm : ndarray or None, shape (height, width)
        The true surface heights rendered, nm, the whole frame (read-only; None without a surface).
    rotation_deg : float
        The part's rotation on its mount rendered, degrees counter-clockwise as displayed.
    reference_waves : ndarray or None, shape (height, width)
        The reference's error in ``wavefront_waves``, waves, NaN outside the aperture (read-only;
        None for a perfect reference). The part as seen is ``wavefront_waves - reference_waves``.
    """

    time_s: float
    modes: tuple[tuple[int, int], ...]
    coefficients_waves: NDArray[np.float64]
    pupil_px: tuple[float, float, float]
    wavefront_waves: NDArray[np.float64]
    mask: NDArray[np.bool_]
    aperture: ApertureShape
    aperture_revision: int
    phase_shift_rad: float = 0.0
    vibration_rad: float = 0.0
    carrier_cycles: tuple[float, float] = (0.0, 0.0)
    surface_revision: int | None = None
    surface_nm: NDArray[np.float64] | None = None
    rotation_deg: float = 0.0
    reference_waves: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class FrameFacts:
    """What one rendered frame was made from, without its wavefront map (:meth:`TestOptic.frame`).

    The map follows from these and the optic (:meth:`TestOptic.truth` at ``time_s``) while the
    optic's aperture and surface revisions are still these.

    Attributes
    ----------
    time_s : float
        Time the frame shows, seconds.
    phase_shift_rad : float
        The ``delta`` applied to the frame, radians.
    vibration_rad : float
        The piston jitter applied to the frame, radians.
    carrier_cycles : (float, float)
        The carrier ``(nx, ny)`` of the frame, fringes across width and height.
    aperture_revision : int
        The optic's aperture revision rendered.
    surface_revision : int or None
        The surface's revision rendered (None: an optic without a surface).

    Example
    -------
    >>> FrameFacts(0.5, 0.0, 0.01, (0.0, 0.0), 0, None).aperture_revision
    0
    """

    time_s: float
    phase_shift_rad: float
    vibration_rad: float
    carrier_cycles: tuple[float, float]
    aperture_revision: int
    surface_revision: int | None
