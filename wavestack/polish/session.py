"""A polishing session: the station's devices opened, the station running on its own thread, the maps flowing.

:func:`open_session` does what ``wavestack polish`` and the end-to-end tests both need before a
campaign: the job folder (``[plc] job_folder``, or a temporary folder for a simulated PLC), the
devices (with ``sim://`` URLs the simulated bench, and a simulated PLC whose polishing machine
polishes the optic's surface), the job ids the share already holds noted as used, the host's TIF
and target figure, and the station's thread feeding a :class:`~wavestack.polish.live_maps.LiveMaps`.
Everything is closed by the caller's ``ExitStack``: the station's thread first, then the station,
then the devices.
"""

from __future__ import annotations

import logging
import tempfile
import threading
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wavestack.config.polishing import PolishingConfig
from wavestack.drivers.plc import PolishingLink, used_job_ids
from wavestack.pipeline import InputError
from wavestack.pipeline.polishing import ToolInfluence
from wavestack.polish.live_maps import LiveMaps
from wavestack.polish.planning import host_tif
from wavestack.station import CycleRecord, ResultSink, Station, StationDevices, open_station_devices

logger = logging.getLogger(__name__)

__all__ = ["PolishingSession", "load_target_figure", "open_session", "session_tif"]


@dataclass(eq=False)
class PolishingSession:
    """What a campaign runs on.

    Attributes
    ----------
    config : PolishingConfig
    devices : StationDevices
    link : PolishingLink
    station : Station
    maps : LiveMaps
    job_folder : Path
    tif : ToolInfluence
        The host's model of the tool.
    target_nm : ndarray (H, W) or None
        The target figure, when configured.
    """

    config: PolishingConfig
    devices: StationDevices
    link: PolishingLink
    station: Station
    maps: LiveMaps
    job_folder: Path
    tif: ToolInfluence
    target_nm: NDArray[np.float64] | None


def session_tif(config: PolishingConfig) -> ToolInfluence:
    """The host's TIF from ``[polishing.tif]`` (a map file relative to the configuration's folder).

    Raises
    ------
    InputError
        A map file that cannot be read or is not a TIF.
    """
    settings = config.polishing
    try:
        return host_tif(settings.tif, settings.pixel_mm, Path(config.source).resolve().parent)
    except (OSError, ValueError) as error:
        raise InputError(f"{config.source}: [polishing.tif]: {error}") from None


def load_target_figure(config: PolishingConfig) -> NDArray[np.float64] | None:
    """``[polishing] target_figure``, a ``.npy`` map in nm of the camera's shape, or None.

    Raises
    ------
    InputError
        Unreadable, not 2-D, or not the simulated camera's shape.
    """
    path = config.resolve(config.polishing.target_figure)
    if path is None:
        return None
    try:
        target = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise InputError(f"{path}: [polishing] target_figure: cannot read a .npy map ({error})") from None
    camera = config.station.camera_simulator
    shape = (camera.height, camera.width)
    if target.ndim != 2 or (config.station.camera.simulated and target.shape != shape):
        raise InputError(f"{path}: [polishing] target_figure: expected a {shape} map in nm, got shape {target.shape}")
    return np.asarray(target, dtype=np.float64)


def _job_folder(config: PolishingConfig, stack: ExitStack) -> Path:
    plc = config.station.plc
    assert plc is not None  # parse_polishing_config requires [plc]
    folder = config.resolve(plc.link.job_folder)
    if folder is not None:
        if not folder.is_dir():
            raise InputError(f"{config.source}: [plc] job_folder = {plc.link.job_folder!r}: no such folder ({folder})")
        return folder
    if not plc.link.simulated:
        raise InputError(f"{config.source}: [plc] job_folder: expected the machine's job folder (a real PLC)")
    return Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="wavestack-jobs-")))


def _serve(stack: ExitStack, station: Station, maps: LiveMaps, sinks: Sequence[ResultSink] = ()) -> None:
    """The station on its own thread until the stack closes (its heartbeat keeps the PLC's watchdog fed).

    ``sinks`` get every record after ``maps`` (the web view).
    """
    halt = threading.Event()

    def on_result(record: CycleRecord) -> None:
        maps(record)
        for sink in sinks:
            sink(record)

    def serve() -> None:
        why = "stopped"
        try:
            station.run(stop=halt, on_result=on_result if sinks else maps)
        except Exception as error:  # the loop sees it as an untrusted measurement or a lost machine
            logger.error("the station stopped: %s", error, exc_info=True)
            why = f"{type(error).__name__}: {error}"
        finally:
            maps.end(why)

    thread = threading.Thread(target=serve, name="polish-station")
    thread.start()

    def stop_serving() -> None:
        halt.set()
        thread.join()

    stack.callback(stop_serving)


def open_session(config: PolishingConfig, stack: ExitStack, *, sinks: Sequence[ResultSink] = ()) -> PolishingSession:
    """Open everything a campaign needs (module notes); ``stack`` closes it all.

    ``sinks`` also get the station's records (the web view).

    Raises
    ------
    InputError
        The job folder, the TIF map or the target figure.
    DeviceError
        A device that does not answer.
    """
    tif = session_tif(config)
    target = load_target_figure(config)
    job_folder = _job_folder(config, stack)
    devices = open_station_devices(config.station, stack, job_folder=job_folder)
    if devices.link is None:
        raise InputError(f"{config.source}: the polishing loop needs the PLC link ([plc], [outputs] enabled = true)")
    devices.link.note_used_job_ids(used_job_ids(job_folder))  # never an id a file in the share already has
    station = Station(config.station, devices)
    stack.callback(station.close)
    maps = LiveMaps()
    _serve(stack, station, maps, sinks)
    return PolishingSession(config, devices, devices.link, station, maps, job_folder, tif, target)
