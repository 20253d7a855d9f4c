"""The alignment measurement through the station: interferograms, phase, unwrapped maps, averaged.

With ``[align] station = "FILE.toml"`` the session opens that station with the station's own
device code (:func:`~wavestack.station.open_station_devices`: a real USB3 Vision camera and piezo,
or the simulated ones), runs it on its own thread feeding a
:class:`~wavestack.polish.live_maps.LiveMaps` (:class:`StationMaps`), and measures a field point
as: wait for ``averaged`` valid maps in a row exposed after the call (the loop calls it once the
field stage and the hexapod are on target), average them on the fixed aperture, subtract the
piston. The fixed aperture is the model's pupil less ``edge_px`` rim pixels (the station's
detected aperture loses a few rim pixels, docs/station.md); a map not finite on it is refused, and
the sensitivity matrix is fitted on the same aperture with the same fitter.

:class:`StationSource` is that measurement, with an optional ``prepare`` step called first: on
the simulated bench it is the coupling of the telescope to the station's test optic
(:class:`~wavestack.simulators.align_bench.SurfaceCoupling`, wired by the session), which returns
the tilt the interferometer's reference took out so that it is added back. On a real bench there
is no such step: the reference's tilt is not known to the loop, which fits and judges without
tilt (:class:`~.terms.TermFitter` ``remove_tilt``).
"""

from __future__ import annotations

import logging
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
from wavestack.config.station_schema import StationConfig
from wavestack.polish.live_maps import LiveMaps
from wavestack.station import Station, StationDevices, open_station_devices

logger = logging.getLogger(__name__)

__all__ = ["StationMaps", "StationSource", "fixed_aperture"]

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


class StationMaps:
    """A station running on its own thread, handing averaged maps to a measurement (module notes).

    Parameters
    ----------
    station_config : Path
        The station TOML (real devices or ``sim://``); its camera grid must be the TMA's.
    stack : ExitStack
        Closes the station's thread, the station and its devices.

    Raises
    ------
    ConfigError, DeviceError
        The station file, or a device that does not open.
    """

    def __init__(self, station_config: Path, stack: ExitStack) -> None:
        self.config: StationConfig = load_station_config(station_config)
        self.devices: StationDevices = open_station_devices(self.config, stack)
        self._maps = LiveMaps()
        self._stop = threading.Event()
        station = Station(self.config, self.devices)
        stack.callback(station.close)
        halt = threading.Event()

        def serve() -> None:
            why = "stopped"
            try:
                station.run(stop=halt, on_result=self._maps)
            except Exception as error:  # the loop sees it as a refused measurement
                logger.error("align: the station stopped: %s", error, exc_info=True)
                why = f"{type(error).__name__}: {error}"
            finally:
                self._maps.end(why)

        thread = threading.Thread(target=serve, name="align-station")
        thread.start()

        def stop_serving() -> None:
            self._stop.set()
            halt.set()
            thread.join()

        stack.callback(stop_serving)

    def average(self, count: int, not_before_ns: int, timeout_s: float) -> NDArray[np.float64]:
        """The mean of ``count`` valid maps in a row exposed at or after ``not_before_ns``, waves (H, W).

        A pixel left out of a map (NaN) is the mean of the maps that measured it; NaN if none did.

        Raises
        ------
        UntrustedMeasurement
            Not enough valid maps in time, or the station stopped.
        """
        samples = self._maps.collect(count, max_results=count * 4, not_before_ns=not_before_ns,
                                     timeout_s=timeout_s, stop=self._stop)
        maps = np.stack([np.asarray(s.waves, dtype=np.float64) for s in samples])
        measured = np.isfinite(maps).sum(axis=0)  # a pixel the quality mask left out of a map: the others'
        total = np.where(np.isfinite(maps), maps, 0.0).sum(axis=0)
        return np.divide(total, measured, out=np.full(total.shape, np.nan), where=measured > 0)


class StationSource:
    """Field-point measurements through a running station (module notes).

    Parameters
    ----------
    maps : StationMaps
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

    def __init__(self, maps: StationMaps, mask: NDArray[np.bool_], *, averaged: int = 3, timeout_s: float = 30.0,
                 settle_s: float = 0.0, prepare: Prepare | None = None) -> None:
        self.maps = maps
        self._mask, self._averaged, self._timeout_s = np.asarray(mask, dtype=bool), averaged, timeout_s
        self._settle_ns = int(round(settle_s * 1e9))
        self._prepare = prepare

    def measure(self, index: int) -> FieldMeasurement:
        """Average the maps exposed ``settle_s`` after this call on the fixed aperture (raises if untrusted)."""
        added = self._prepare() if self._prepare is not None else None
        after = time.time_ns() + self._settle_ns
        waves = self.maps.average(self._averaged, after, self._timeout_s + self._settle_ns * 1e-9)
        if added is not None:
            waves = waves + added
        if not np.all(np.isfinite(waves[self._mask])):
            raise ValueError(f"field point {index}: the station's maps do not cover the fixed aperture")
        waves = np.where(self._mask, waves - waves[self._mask].mean(), np.nan)  # piston is arbitrary
        return FieldMeasurement(waves, after)
