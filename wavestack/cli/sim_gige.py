"""``wavestack sim gige``: serve a simulated GigE Vision camera (GVCP and GVSP on UDP) until stopped.

The camera looks at the simulated test optic of a station file (its ``[optic]`` and
``[camera.simulator]``), or serves a real vendor's XML and register map. Any GigE Vision software
can then talk to it: ``wavestack run`` with ``[camera] url = "gige://HOST:PORT"``, or aravis'
``arv-tool-0.8 -a HOST`` when it listens on GVCP's own port 3956.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

from wavestack.cli.sim_plc import check_bind
from wavestack.config import load_station_config
from wavestack.simulators.bench import SimulatedInterferometer
from wavestack.simulators.genicam import PERSONALITIES
from wavestack.simulators.gige import GigESimSettings
from wavestack.simulators.optic import TestOptic

__all__ = ["run_gige_simulator"]

_log = logging.getLogger(__name__)
_STOP_POLL_S = 0.1


def run_gige_simulator(config_path: Path | None, host: str, port: int, allow_remote: bool,
                       announce: Callable[[str], None], stop: threading.Event, *, vendor: str | None = None,
                       vendor_xml: Path | None = None) -> None:
    """Run the simulated GigE Vision camera until ``stop`` is set.

    Parameters
    ----------
    config_path
        Station TOML whose ``[optic]`` and ``[camera.simulator]`` describe what the camera sees;
        None for the packaged default station.
    host, port
        Where GVCP listens; port 0 picks a free port, 3956 is GigE Vision's own.
    allow_remote
        Allow a non-loopback host. GVCP has no authentication: anyone who reaches the port can
        take control of the (simulated) camera.
    announce
        Called once with ``"listening HOST:PORT"`` when the camera answers.
    stop
        Set it to stop the camera (the CLI sets it on SIGINT/SIGTERM).
    vendor, vendor_xml
        A real camera's register map (one of :data:`wavestack.simulators.genicam.PERSONALITIES`) and
        the path of its GenApi XML, served instead of the simulator's own XML.

    Raises
    ------
    ValueError
        A non-loopback host without ``allow_remote``, a port outside 0..65535, an unknown vendor,
        or an address the camera cannot bind.
    ConfigError
        A bad station file (or one without ``[optic]``).
    """
    check_bind(host, port, allow_remote, simulator="the GigE Vision camera simulator", protocol="GVCP")
    if (vendor is None) != (vendor_xml is None) or (vendor is not None and vendor not in PERSONALITIES):
        raise ValueError(f"--vendor and --vendor-xml go together; vendors: {sorted(PERSONALITIES)}")
    config = load_station_config(config_path)
    sim = config.camera_simulator
    if config.optic is None:
        raise ValueError(f"{config.source}: the GigE camera simulator needs an [optic] table (what it looks at)")
    settings = GigESimSettings(serial=sim.serial[:16], width=sim.width, height=sim.height,
                               pixel_format=sim.pixel_format, frame_rate_hz=sim.frame_rate_hz, host=host, port=port,
                               vendor=vendor, vendor_xml=None if vendor_xml is None else str(vendor_xml))
    try:
        bench = SimulatedInterferometer(TestOptic(config.optic, sim.height, sim.width), settings)
    except OSError as error:
        raise ValueError(f"cannot serve the GigE camera simulator on {host}:{port}: {error}") from None
    camera = bench.camera
    with camera:  # type: ignore[attr-defined]
        announce(f"listening {camera.host}:{camera.port}")  # type: ignore[attr-defined]
        while not stop.wait(_STOP_POLL_S):
            pass
    _log.info("GigE camera simulator on %s:%d stopped", host, camera.port)  # type: ignore[attr-defined]
