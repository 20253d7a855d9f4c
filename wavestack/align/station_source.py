"""The alignment measurement through the station: interferograms, phase, unwrapped maps, averaged.

With ``[align] station = "FILE.toml"`` the session opens that station as the station service
(:class:`~wavestack.station.StationService`: the station's own device code, a real USB3 Vision
camera and piezo or the simulated ones, the station on its own thread feeding its averaged maps),
and measures a field point as: wait for ``averaged`` valid maps in a row exposed after the call
(the loop calls it once the field stage and the hexapod are on target), average them on the
fixed aperture, subtract the piston. The fixed aperture is the model's pupil less ``edge_px`` rim pixels (the station's
detected aperture loses a few rim pixels, docs/station.md); a map not finite on it is refused, and
the sensitivity matrix is fitted on the same aperture with the same fitter.

:class:`StationSource` is that measurement, with an optional ``prepare`` step called first: on
the simulated bench it is the coupling of the telescope to the station's test optic
(the simulated bench's surface coupling, wired by the simulator starter), which returns
the tilt the interferometer's reference took out so that it is added back. On a real bench there
is no such step: the reference's tilt is not known to the loop, which fits and judges without
tilt (:class:`~.terms.TermFitter` ``remove_tilt``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from wavestack.align.loop import FieldMeasurement
from wavestack.config.station import load_station_config
from wavestack.station import StationService

__all__ = ["StationSource", "fixed_aperture", "open_station_service"]

#: ``prepare()`` before a measurement: returns a map (H, W) to add to the averaged maps (waves), or None.
Prepare = Callable[[], NDArray[np.float64] | None]


def fixed_aperture(pupil: NDArray[np.bool_], edge_px: int) -> NDArray[np.bool_]:
    """The pupil less ``edge_px`` rim pixels (3 x 3 erosions).

    Example
    -------
    >>> mask = np.zeros((9, 9), bool); mask[1:8, 1:8] = True
    >>> int(fixed_aperture(mask, 2).sum())
    9
    """
    if edge_px <= 0:
        return np.asarray(pupil, dtype=bool).copy()
    return ndimage.binary_erosion(pupil, structure=np.ones((3, 3), bool), iterations=edge_px)


def open_station_service(station_config: Path, stack: ExitStack) -> StationService:
    """The station of ``[align] station`` running as a service (its camera grid must be the TMA's).

    Raises
    ------
    ConfigError, DeviceError
        The station file, or a device that does not open.
    """
    return StationService(load_station_config(station_config), stack, name="align-station")


class StationSource:
    """Field-point measurements through a running station (module notes).

    Parameters
    ----------
    service : StationService
    mask : ndarray (H, W) of bool
        The fixed aperture.
    averaged : int
        Valid maps averaged per field point.
    timeout_s : float
        Longest wait for them.
    settle_s : float
        Maps count only if exposed this long after the call (the platform's ringing, the remote
        bench's render), s.
    prepare : callable, optional
        Called before each measurement; a map it returns is added to the average (the simulated
        bench's reference tilt).
    """

    def __init__(self, service: StationService, mask: NDArray[np.bool_], *, averaged: int = 3,
                 timeout_s: float = 30.0, settle_s: float = 0.0, prepare: Prepare | None = None) -> None:
        self.service = service
        self._stop = threading.Event()
        self._mask, self._averaged, self._timeout_s = np.asarray(mask, dtype=bool), averaged, timeout_s
        self._settle_ns = int(round(settle_s * 1e9))
        self._prepare = prepare

    def measure(self, index: int) -> FieldMeasurement:
        """Average the maps exposed ``settle_s`` after this call on the fixed aperture (raises if untrusted)."""
        added = self._prepare() if self._prepare is not None else None
        after = time.time_ns() + self._settle_ns
        waves = self.service.maps.average(self._averaged, not_before_ns=after,
                                          timeout_s=self._timeout_s + self._settle_ns * 1e-9, stop=self._stop)
        if added is not None:
            waves = waves + added
        if not np.all(np.isfinite(waves[self._mask])):
            raise ValueError(f"field point {index}: the station's maps do not cover the fixed aperture")
        waves = np.where(self._mask, waves - waves[self._mask].mean(), np.nan)  # piston is arbitrary
        return FieldMeasurement(waves, after)
