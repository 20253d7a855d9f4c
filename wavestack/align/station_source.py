"""The alignment measurement through the station: interferograms, phase, unwrapped maps, averaged.

With ``[align] station = "FILE.toml"`` the session opens that station (a simulated U3V camera
and piezo looking at a test optic whose surface the alignment bench sets,
:class:`~wavestack.simulators.align_bench.SurfaceCoupling`), runs it on its own thread feeding a
:class:`~wavestack.polish.live_maps.LiveMaps`, and measures a field point as: put the bench's
wavefront on the optic (the field stage and hexapod poses of now), wait for ``averaged`` valid
maps in a row exposed after that, average them on the fixed aperture, and add back the tilt the
interferometer's reference took out (the return spot centred at each field point: without it the
fringes of a misaligned secondary alias on the camera, :mod:`.fringes`). The fixed aperture is the
model's pupil less ``edge_px`` rim pixels (the station's detected aperture loses a few rim pixels,
docs/station.md); a map not finite on it is refused, and the sensitivity matrix is fitted on the
same aperture with the same fitter.
"""

from __future__ import annotations

import logging
import threading
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from wavestack.align.loop import FieldMeasurement
from wavestack.config.station import load_station_config
from wavestack.polish.live_maps import LiveMaps
from wavestack.simulators.align_bench import AlignmentBench, SurfaceCoupling
from wavestack.station import Station, open_station_devices

logger = logging.getLogger(__name__)

__all__ = ["StationSource", "fixed_aperture"]


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


class StationSource:
    """Field-point measurements through a running simulated station (module notes).

    Parameters
    ----------
    station_config : Path
        The station TOML (its camera grid must be the TMA's camera grid, its optic a surface).
    bench : AlignmentBench
    mask : ndarray (H, W) of bool
        The fixed aperture.
    stack : ExitStack
        Closes the station's thread, the station and its devices.
    averaged : int
        Valid maps averaged per field point.
    timeout_s : float
        Longest wait for them.
    null_tilt : bool
        The reference takes out the tilt before the maps are taken; it is added back from the
        reference's setting (:class:`~wavestack.simulators.align_bench.SurfaceCoupling`).
    """

    def __init__(self, station_config: Path, bench: AlignmentBench, mask: NDArray[np.bool_], stack: ExitStack, *,
                 averaged: int = 3, timeout_s: float = 30.0, null_tilt: bool = True) -> None:
        config = load_station_config(station_config)
        devices = open_station_devices(config, stack)
        optic = getattr(devices.bench, "optic", None)
        surface = getattr(optic, "surface", None)
        reflection = getattr(getattr(config.optic, "surface", None), "reflection_factor", 2.0)
        self._coupling = SurfaceCoupling(bench, surface, config.station.wavelength_nm, reflection, null_tilt=null_tilt)
        self._mask, self._averaged, self._timeout_s = np.asarray(mask, dtype=bool), averaged, timeout_s
        self._maps = LiveMaps()
        self._stop = threading.Event()
        station = Station(config, devices)
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

    def measure(self, index: int) -> FieldMeasurement:
        """Put the current wavefront on the optic, average the maps exposed after, add back the reference's
        tilt (raises if untrusted)."""
        _, tilt = self._coupling.refresh()
        after = time.time_ns()
        samples = self._maps.collect(self._averaged, max_results=self._averaged * 4, not_before_ns=after,
                                     timeout_s=self._timeout_s, stop=self._stop)
        stack = np.array([np.asarray(s.waves, dtype=np.float64) for s in samples])
        waves = stack.mean(axis=0) + tilt.plane(stack.shape[1:])
        if not np.all(np.isfinite(waves[self._mask])):
            raise ValueError(f"field point {index}: the station's maps do not cover the fixed aperture")
        waves = np.where(self._mask, waves - waves[self._mask].mean(), np.nan)  # piston is arbitrary
        return FieldMeasurement(waves, after)
