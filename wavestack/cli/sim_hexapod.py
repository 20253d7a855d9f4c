"""``wavestack sim hexapod``: serve the simulated PI C-887 hexapod controller on TCP until stopped.

Any GCS 2.0 host (the wavestack driver, PI's own software, a plain socket tool) can then connect to
the announced address and speak GCS as to a real controller.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

from wavestack.cli.bind import check_bind
from wavestack.config.hexapod_sim import load_hexapod_sim_config
from wavestack.simulated import hexapod_settings
from wavestack.simulators.pi_gcs import HexapodSimulator

__all__ = ["run_hexapod_simulator"]

_log = logging.getLogger(__name__)
_STOP_POLL_S = 0.1


def run_hexapod_simulator(config_path: Path | None, host: str, port: int, allow_remote: bool,
                          announce: Callable[[str], None], stop: threading.Event) -> None:
    """Run the hexapod simulator until ``stop`` is set.

    Parameters
    ----------
    config_path
        TOML with ``[hexapod.simulator]``; None for the built-in six-axis hexapod.
    host, port
        Where to listen; port 0 picks a free port.
    allow_remote
        Allow a non-loopback host. GCS over TCP has no authentication: anyone who can reach the
        port can move the (simulated) platform.
    announce
        Called once with ``"listening HOST:PORT"`` when the server accepts connections.
    stop
        Set it to stop the server (the CLI sets it on SIGINT/SIGTERM).

    Raises
    ------
    ValueError
        A non-loopback host without ``allow_remote``, a port outside 0..65535, or a host/port the
        server cannot bind.
    ConfigError
        A bad configuration.
    """
    check_bind(host, port, allow_remote, simulator="the hexapod simulator", protocol="GCS over TCP")
    settings = hexapod_settings(load_hexapod_sim_config(config_path), source=str(config_path or "the built-in hexapod"))
    simulator = HexapodSimulator(settings, host=host, port=port)
    try:
        simulator.start()
    except OSError as error:
        raise ValueError(f"cannot serve the hexapod simulator on {host}:{port}: {error}") from None
    try:
        announce(f"listening {host}:{simulator.port}")
        while not stop.wait(_STOP_POLL_S):
            pass
    finally:
        simulator.stop()
        _log.info("hexapod simulator on %s:%d stopped", host, simulator.port)
