"""The station as a service: its devices opened, the station on its own thread, its records to every sink.

The closed loops (``wavestack polish``, ``wavestack align``) run beside a live station rather than
inside it: the station's thread keeps measuring and keeps the PLC's heartbeat going for the whole
loop, whether the loop measures, solves, waits for a machine or moves a platform. A
:class:`StationService` is that arrangement, in one place: it opens the devices
(:func:`~wavestack.station.devices.open_station_devices`), runs the
:class:`~wavestack.station.station.Station` on a thread named for its user, hands every
:class:`~wavestack.station.cycle.CycleRecord` to its averaged maps
(:class:`~wavestack.station.live_maps.LiveMaps`, which also keeps the latest PLC status) and then
to the extra sinks (the web view), and tells the maps why it stopped, so a waiting measurement
gives up at once. Everything is closed by the caller's ``ExitStack``: the station's thread
first, then the station, then the devices.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path

from wavestack.config import StationConfig
from wavestack.station.cycle import CycleRecord, ResultSink
from wavestack.station.devices import StationDevices, open_station_devices
from wavestack.station.live_maps import LiveMaps
from wavestack.station.plc_status import Heartbeat
from wavestack.station.station import Station

logger = logging.getLogger(__name__)

__all__ = ["StationService"]


class StationService:
    """A station running on its own thread for a loop (module notes).

    Parameters
    ----------
    config : StationConfig
    stack : ExitStack
        Closes the station's thread, the station and its devices.
    sinks : sequence of ResultSink
        Get every record after the averaged maps (the web view).
    job_folder : Path, optional
        The polishing machine's job folder, for a simulated PLC's machine.
    name : str
        The thread's name (``"polish-station"``, ``"align-station"``).

    Attributes
    ----------
    config : StationConfig
    devices : StationDevices
    station : Station
    maps : LiveMaps

    Raises
    ------
    DeviceError
        A device that does not answer at start.
    """

    def __init__(self, config: StationConfig, stack: ExitStack, *, sinks: Sequence[ResultSink] = (),
                 job_folder: Path | None = None, name: str = "station-service") -> None:
        self.config = config
        self.devices: StationDevices = open_station_devices(config, stack, job_folder=job_folder)
        self.station = Station(config, self.devices)
        stack.callback(self.station.close)
        self.maps = LiveMaps()
        self._sinks = tuple(sinks)
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._serve, name=name)
        self._thread.start()
        stack.callback(self._stop)

    @property
    def last_heartbeat(self) -> Heartbeat | None:
        """The PLC status of the station's latest result (None before any, or without a PLC)."""
        return self.maps.last_heartbeat

    def _on_result(self, record: CycleRecord) -> None:
        self.maps(record)
        for sink in self._sinks:
            sink(record)

    def _serve(self) -> None:
        why = "stopped"
        try:
            self.station.run(stop=self._halt, on_result=self._on_result if self._sinks else self.maps)
        except Exception as error:  # a loop sees it as an untrusted measurement or a lost machine
            logger.error("the station stopped: %s", error, exc_info=True)
            why = f"{type(error).__name__}: {error}"
        finally:
            self.maps.end(why)

    def _stop(self) -> None:
        self._halt.set()
        self._thread.join()
