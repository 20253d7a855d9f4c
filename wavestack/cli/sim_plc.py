"""``wavestack sim plc``: serve the simulated polishing-station PLC on Modbus/TCP until stopped."""

from __future__ import annotations

import logging
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from wavestack.cli.bind import check_bind
from wavestack.config import ConfigError, load_plc_config
from wavestack.simulated import machine_settings, plc_layout, polishing_machine, polishing_station
from wavestack.simulators.plc.server import PlcSimulator

__all__ = ["run_plc_simulator"]

_log = logging.getLogger(__name__)


def run_plc_simulator(config_path: Path | None, host: str, port: int, allow_remote: bool,
                      announce: Callable[[str], None], stop: threading.Event, *,
                      job_folder: Path | None = None) -> None:
    """Run the PLC simulator until ``stop`` is set.

    Parameters
    ----------
    config_path
        TOML with ``[plc]`` and ``[plc.simulator.polishing]``, and ``[plc.simulator.machine]`` for a
        machine that runs jobs; None for the built-in defaults (equal to ``config/plc-sim.toml``).
    host, port
        Where to listen; port 0 picks a free port.
    allow_remote
        Allow a non-loopback host. Modbus/TCP has no authentication: anyone who can reach the port
        can command the (simulated) machine.
    announce
        Called once with ``"listening HOST:PORT"`` when the server accepts connections.
    stop
        Set it to stop the server (the CLI sets it on SIGINT/SIGTERM).
    job_folder
        Run a polishing machine on this job folder (also without ``[plc.simulator.machine]``: its
        defaults). The standalone machine polishes no optic: it checks and runs jobs, reporting
        progress. Without it, a machine runs only if the configuration has that table.

    Raises
    ------
    ValueError
        A non-loopback host without ``allow_remote``, a port outside 0..65535, or a host/port the
        server cannot bind.
    ConfigError
        A bad configuration, or one without ``[plc.simulator]``.
    """
    check_bind(host, port, allow_remote, simulator="the PLC simulator", protocol="Modbus/TCP")
    config = load_plc_config(config_path)
    if config.simulator is None:
        raise ConfigError(f"{config.source}: no [plc.simulator] table; the simulator needs the polishing model "
                          "(see config/plc-sim.toml)")
    machine = None
    if job_folder is not None or config.simulator.machine is not None:
        if not Path(machine_folder := str(job_folder or machine_settings(config).job_folder)).is_dir():
            raise ValueError(f"the machine's job folder {machine_folder} does not exist or is not a folder")
        machine = polishing_machine(config, None, job_folder)
    simulator = PlcSimulator(plc_layout(config), polishing_station(config), host=host, port=port, machine=machine)
    try:
        simulator.start()
    except OSError as error:
        raise ValueError(f"cannot serve the PLC simulator on {host}:{port}: {error}") from None
    try:
        if machine is not None:  # on stderr: the announced line stays exactly 'listening HOST:PORT' for scripts
            print(f"wavestack sim plc: polishing machine on job folder {machine.settings.job_folder}", file=sys.stderr)
        announce(f"listening {host}:{simulator.port}")
        while not stop.wait(0.1):
            pass
    finally:
        simulator.stop()
        _log.info("PLC simulator on %s:%d stopped", host, simulator.port)
