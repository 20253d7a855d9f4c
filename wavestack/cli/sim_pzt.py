"""``wavestack sim pzt``: serve the simulated MDT693B on a pseudo-terminal until told to stop.

Any serial program (the wavestack driver, a terminal emulator, another lab's software) can then open
the announced path as if it were ``/dev/ttyUSB0``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from wavestack.config import load_pzt_config, parse_pzt_config
from wavestack.simulated import piezo_device
from wavestack.simulators.mdt693b import PtyBridge

logger = logging.getLogger(__name__)

_STOP_POLL_S = 0.2  # how often the serving loop looks at `stop` (bounded wait keeps signals responsive)


def default_pzt_config() -> dict[str, Any]:
    """The settings of ``config/pzt-sim.toml``, built in so an installed package needs no file."""
    return {
        "pzt": {
            "url": "sim://mdt693b",
            "axes": ["x"],
            "phase_axis": "x",
            "software_min_v": 0.0,
            "software_max_v": 150.0,
            "readback_tolerance_v": 0.5,
            "timeout_s": 1.0,
            "volts_per_radian": 2.0,
            "bias_v": 75.0,
            "settle_s": 0.02,
            "simulator": {
                "model": "MDT693B",
                "echo": True,
                "prompt": ">",
                "firmware": "1.10",
                "serial_number": "SIM-000001",
                "vlimit_v": 150.0,
            },
        }
    }


def run_pzt_simulator(config_path: Path | None, announce: Callable[[str], None], stop: threading.Event) -> None:
    """Serve the configured simulated controller on a pty until ``stop`` is set.

    Parameters
    ----------
    config_path
        TOML file with ``[pzt]`` and ``[pzt.simulator]``; None uses :func:`default_pzt_config`.
    announce
        Called once with ``"pty /dev/pts/N"`` when the pty is ready.
    stop
        Set it (from a signal handler or another thread) to stop; the pty is closed on return.

    Raises
    ------
    ConfigError
        The configuration does not validate.
    """
    if config_path is None:
        _, simulator = parse_pzt_config(default_pzt_config(), source="built-in pzt simulator defaults")
    else:
        _, simulator = load_pzt_config(config_path)
    device = piezo_device(simulator)
    with PtyBridge(device) as bridge:
        announce(f"pty {bridge.port_path}")
        while not stop.wait(_STOP_POLL_S):
            pass
    logger.info("pzt simulator on %s stopped", bridge.port_path)
