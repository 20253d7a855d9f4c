"""A polishing session: the station service running, the job folder, the host's tool model and target figure.

:func:`open_session` does what ``wavestack polish`` and the end-to-end tests both need before a
campaign: the job folder (``[plc] job_folder``, or a temporary folder for a simulated PLC), the
station service (:class:`~wavestack.station.StationService`: the devices, with ``sim://`` URLs the
simulated bench and a simulated PLC whose polishing machine polishes the optic's surface; the
station on its own thread feeding its averaged maps), the job ids the share already holds noted
as used, and the host's TIF and target figure. Everything is closed by the caller's ``ExitStack``:
the station's thread first, then the station, then the devices.
"""

from __future__ import annotations

import logging
import tempfile
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
from wavestack.polish.planning import host_tif
from wavestack.station import LiveMaps, ResultSink, Station, StationDevices, StationService

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
    if config.station.plc is None or not config.station.outputs.enabled:
        raise InputError(f"{config.source}: the polishing loop needs the PLC link ([plc], [outputs] enabled = true)")
    service = StationService(config.station, stack, sinks=sinks, job_folder=job_folder, name="polish-station")
    link = service.devices.link
    assert link is not None  # [plc] with outputs enabled opens the link
    link.note_used_job_ids(used_job_ids(job_folder))  # never an id a file in the share already has
    return PolishingSession(config, service.devices, link, service.station, service.maps, job_folder, tif, target)
