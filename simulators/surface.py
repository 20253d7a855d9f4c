"""The simulated optic's surface: a thread-safe height map that polishing changes and everyone reads.

:class:`SurfaceState` holds the heights (nm) of the test optic on the camera grid, the aperture
and its margin alike. The simulated polishing machine takes material away
(:meth:`SurfaceState.apply_removal`); the optic renders what is there now; tests read the truth.

Copy-on-write: every change builds a new array and swaps it in under a lock, so a snapshot once
handed out (:meth:`SurfaceState.heights_nm`) is never mutated afterwards, and readers never wait
for more than the swap. Every change raises :attr:`SurfaceState.revision` by one, so a reader
that cached something made from a snapshot knows when it is stale.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.simulators._checks import finite_number, read_only

__all__ = ["SurfaceSnapshot", "SurfaceState"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SurfaceSnapshot:
    """The heights and the revision they belong to, taken together.

    Attributes
    ----------
    revision : int
        0 for the initial surface, +1 per change.
    heights_nm : ndarray of float64, shape (H, W)
        Surface heights, nm (read-only, never mutated).
    """

    revision: int
    heights_nm: NDArray[np.float64]


class SurfaceState:
    """The mutable, thread-safe height map of the simulated optic's surface.

    Parameters
    ----------
    heights_nm : array_like, shape (H, W)
        Initial heights, nm, finite everywhere (copied).
    pixel_mm : float
        Size of a grid pixel on the optic, mm, ``> 0``.

    Raises
    ------
    ValueError
        If ``heights_nm`` is not a finite 2-D real array or ``pixel_mm`` is not ``> 0``.

    Examples
    --------
    >>> surface = SurfaceState(np.zeros((4, 5)), pixel_mm=0.5)
    >>> surface.apply_removal(np.full((4, 5), 2.0))
    >>> surface.revision, float(surface.heights_nm()[0, 0])
    (1, -2.0)
    """

    def __init__(self, heights_nm: ArrayLike, pixel_mm: float) -> None:
        heights = _checked_map(heights_nm, "heights_nm", None)
        self._pixel_mm = finite_number(pixel_mm, "pixel_mm", above=0.0)
        self._lock = threading.Lock()
        self._snapshot = SurfaceSnapshot(0, read_only(heights))

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the grid, pixels."""
        return self._snapshot.heights_nm.shape  # type: ignore[return-value]

    @property
    def pixel_mm(self) -> float:
        """Size of a grid pixel on the optic, mm."""
        return self._pixel_mm

    @property
    def revision(self) -> int:
        """0 for the initial surface, +1 per :meth:`apply_removal`."""
        return self._snapshot.revision

    def heights_nm(self) -> NDArray[np.float64]:
        """The current heights, nm, shape (H, W): a read-only snapshot, never mutated afterwards."""
        return self._snapshot.heights_nm

    def snapshot(self) -> SurfaceSnapshot:
        """The current heights with their revision, taken at one instant."""
        return self._snapshot

    def apply_removal(self, removal_nm: ArrayLike) -> None:
        """Take material away: ``heights -= removal_nm``, then ``revision += 1``.

        Concurrent calls are serialised: none is lost.

        Parameters
        ----------
        removal_nm : array_like, shape (H, W)
            Material removed, nm (positive lowers the surface), finite everywhere.

        Raises
        ------
        ValueError
            If ``removal_nm`` is not a finite real array of the grid's shape; nothing changes then.
        """
        removal = _checked_map(removal_nm, "removal_nm", self.shape)
        with self._lock:
            current = self._snapshot
            self._snapshot = SurfaceSnapshot(current.revision + 1, read_only(current.heights_nm - removal))
        logger.debug("surface revision %d", current.revision + 1)


def _checked_map(values: ArrayLike, name: str, shape: tuple[int, int] | None) -> NDArray[np.float64]:
    """``values`` as a new float64 (H, W) array, checked: real, 2-D (of ``shape`` if given), finite."""
    array = np.asarray(values)
    if array.dtype == np.bool_ or not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise ValueError(f"{name}: expected a real array of nm, got dtype {array.dtype}")
    if array.ndim != 2 or 0 in array.shape:
        raise ValueError(f"{name}: expected a 2-D array, got shape {array.shape}")
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name}: expected shape {shape} (the surface grid), got {array.shape}")
    result = np.array(array, dtype=np.float64)
    if not np.isfinite(result).all():
        bad = int(np.count_nonzero(~np.isfinite(result)))
        raise ValueError(f"{name}: expected finite values, got {bad} NaN or infinite")
    return result
