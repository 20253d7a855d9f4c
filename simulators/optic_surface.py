"""The test optic's surface as the camera sees it: its phase, re-made only when the surface changes.

:class:`SurfacePhase` turns a :class:`~wavestack.simulators.surface.SurfaceState` into what
:class:`~wavestack.simulators.optic.TestOptic` renders frames from. The surface adds
``waves_per_nm * heights`` (waves) to the optic's Zernike wavefront on the aperture pixels; the
sum is wrapped to ``[0, 2 pi)`` before the cast to float32 (as the optic does), so float32 holds
the phase to ``2.4e-7`` rad whatever the heights. The result is cached per (aperture revision,
surface revision): a frame of an unchanged surface costs one revision check, and a change costs
a gather, a wrap and a scatter over the aperture pixels once.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators._checks import read_only
from wavestack.simulators.surface import SurfaceState

__all__ = ["SurfacePhase", "SurfaceView"]

_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True, eq=False)
class SurfaceView:
    """The optic's phase and wavefront with one surface revision on one aperture revision.

    Attributes
    ----------
    aperture_revision, surface_revision : int
        What the view was made from.
    heights_nm : ndarray of float64, shape (H, W)
        The surface snapshot, nm (read-only).
    phase : ndarray of float32, shape (H, W)
        ``2 pi (W0 + surface) + carrier`` modulo ``2 pi`` inside the aperture, the optic's own
        phase outside (read-only).
    wavefront : ndarray of float64, shape (H, W)
        ``W0 + waves_per_nm * heights`` in waves, NaN outside the aperture (read-only).
    """

    aperture_revision: int
    surface_revision: int
    heights_nm: NDArray[np.float64]
    phase: NDArray[np.float32]
    wavefront: NDArray[np.float64]


class SurfacePhase:
    """The cache of the surface's contribution to the optic's frames.

    Parameters
    ----------
    state : SurfaceState
        The surface (on the optic's grid).
    waves_per_nm : float
        Wavefront per surface height, waves per nm (``reflection_factor / wavelength_nm``).
    """

    def __init__(self, state: SurfaceState, waves_per_nm: float) -> None:
        self._state = state
        self._waves_per_nm = float(waves_per_nm)
        self._lock = threading.Lock()  # one re-make at a time; readers of a fresh view do not wait
        self._view: SurfaceView | None = None

    @property
    def state(self) -> SurfaceState:
        """The surface."""
        return self._state

    def view(
        self,
        aperture_revision: int,
        index: NDArray[np.intp],
        base_phase: NDArray[np.float64],
        phase: NDArray[np.float32],
        wavefront: NDArray[np.float64],
    ) -> SurfaceView:
        """The view of the current surface on an aperture, re-made if either changed.

        Parameters
        ----------
        aperture_revision : int
            The aperture's revision (the key of ``index``, ``base_phase``, ``phase``, ``wavefront``).
        index : ndarray of intp, shape (N,)
            Flat indices of the aperture pixels, row-major.
        base_phase : ndarray of float64, shape (N,)
            ``2 pi W0 + carrier`` on those pixels, radians, not wrapped.
        phase : ndarray of float32, shape (H, W)
            The optic's phase without the surface (its values outside the aperture are kept).
        wavefront : ndarray of float64, shape (H, W)
            ``W0`` in waves, NaN outside the aperture.

        Returns
        -------
        SurfaceView
        """
        snapshot = self._state.snapshot()
        view = self._view
        if view is not None and (view.aperture_revision, view.surface_revision) == (aperture_revision, snapshot.revision):
            return view
        with self._lock:
            snapshot = self._state.snapshot()  # the newest: a view made here is never older than the last
            view = self._view
            if view is None or (view.aperture_revision, view.surface_revision) != (aperture_revision, snapshot.revision):
                view = self._make(aperture_revision, snapshot.revision, snapshot.heights_nm, index, base_phase,
                                  phase, wavefront)
                self._view = view
        return view

    def _make(self, aperture_revision: int, surface_revision: int, heights: NDArray[np.float64],
              index: NDArray[np.intp], base_phase: NDArray[np.float64], phase: NDArray[np.float32],
              wavefront: NDArray[np.float64]) -> SurfaceView:
        waves = np.take(heights, index)
        waves *= self._waves_per_nm
        inside = base_phase + _TWO_PI * waves
        inside -= _TWO_PI * np.floor(inside * (1.0 / _TWO_PI))  # wrapped (np.mod is ~20x slower per element)
        new_phase = phase.copy()
        new_phase.reshape(-1)[index] = inside  # cast to float32 after the wrap
        new_wavefront = wavefront.copy()
        new_wavefront.reshape(-1)[index] = np.take(wavefront, index) + waves
        return SurfaceView(aperture_revision=aperture_revision, surface_revision=surface_revision, heights_nm=heights,
                           phase=read_only(new_phase), wavefront=read_only(new_wavefront))
