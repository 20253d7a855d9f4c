"""Start the simulated devices a station file's ``sim://`` URLs ask for, so nothing has to be launched by hand.

The test optic and the camera that looks at it (USB3 Vision through a pyusb backend, or GigE
Vision on loopback), through an interferometer or behind a lenslet array for a Shack-Hartmann
station; the MDT693B behind
``sim://mdt693b/NAME`` (wired to the camera, so the fringes move with its voltage); the polishing
PLC on a free loopback port, with a polishing machine that polishes the optic's surface. The
station's drivers then open them exactly as they open hardware: :func:`start_simulated_station`
returns what they need (the camera's backend or URL, the piezo's URL, the PLC's address) and the
simulators themselves (the bench holds the ground truth the tests and the truth check read).
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.config import BIT_DEPTH, StationConfig
from wavestack.simulated.settings import (
    as_simulator,
    camera_settings,
    piezo_device,
    plc_layout,
    polishing_machine,
    polishing_station,
)
from wavestack.simulators import attach_simulated_device, register_serial_simulators
from wavestack.simulators.bench import PiezoCoupling, SimulatedInterferometer, SimulatedShackHartmann
from wavestack.simulators.gige import SimulatedGigECamera
from wavestack.simulators.optic import OpticSettings, TestOptic
from wavestack.simulators.plc import PlcSimulator, PolishingMachine
from wavestack.simulators.spots import LensletArraySettings, SpotRenderer

logger = logging.getLogger(__name__)

__all__ = ["SimulatedStation", "simulated_interferometer", "start_simulated_station"]

SimulatedBench = SimulatedInterferometer | SimulatedShackHartmann


@dataclass(eq=False)
class SimulatedStation:
    """The simulators behind a station's ``sim://`` URLs.

    Attributes
    ----------
    bench : SimulatedInterferometer or SimulatedShackHartmann or None
        The simulated camera's bench (its ``backend`` for a USB3 Vision driver, its ground truth).
    camera_url : str or None
        The GigE Vision URL of the bench's camera, started on loopback (``sim://gige``).
    piezo_url : str or None
        The URL the piezo driver opens (``sim://mdt693b/NAME``, the device attached under NAME).
    plc_simulator : PlcSimulator or None
        The running PLC simulator (its ``host`` and ``port`` for the link).
    """

    bench: SimulatedBench | None = None
    camera_url: str | None = None
    piezo_url: str | None = None
    plc_simulator: PlcSimulator | None = None


def _optic(config: StationConfig) -> TestOptic:
    assert config.optic is not None  # parse_station_config requires [optic] for sim://u3v
    sim = config.camera_simulator
    optic = as_simulator(config.optic, OpticSettings, source=config.source, table="optic")
    if optic.bit_depth != BIT_DEPTH[sim.pixel_format]:
        raise ValueError(f"{config.source}: [optic] bit_depth {optic.bit_depth} does not match "
                         f"[camera.simulator] pixel_format {sim.pixel_format!r}")
    return TestOptic(optic, sim.height, sim.width)


def simulated_interferometer(config: StationConfig) -> tuple[SimulatedInterferometer, Any]:
    """The simulated interferometer a ``sim://u3v`` station file describes, and its piezo device (or None).

    Also used by the remote alignment-bench simulator, which serves them from another process.
    """
    device = None
    if config.pzt is not None and config.pzt.url.startswith("sim://"):
        assert config.pzt_simulator is not None
        device = piezo_device(config.pzt_simulator)
    coupling = as_simulator(config.bench, PiezoCoupling, source=config.source, table="bench")
    bench = SimulatedInterferometer(_optic(config), camera_settings(config.camera, config.camera_simulator), device,
                                    coupling)
    return bench, device


def _simulated_shack_hartmann(config: StationConfig) -> SimulatedShackHartmann:
    sim = config.camera_simulator
    assert config.lenslets is not None  # required by parse_station_config
    lenslets = as_simulator(config.lenslets, LensletArraySettings, source=config.source, table="lenslets")
    spots = SpotRenderer(_optic(config), lenslets, sim.height, sim.width)
    return SimulatedShackHartmann(spots, camera_settings(config.camera, sim))


def _piezo_url(url: str, name: str) -> str:
    """``sim://mdt693b`` gets a device name so the station's bench and driver share one device."""
    scheme_and_model, _, rest = url.partition("?")
    if scheme_and_model.count("/") == 2:  # sim://model without a name
        scheme_and_model = f"{scheme_and_model.rstrip('/')}/{name}"
    return scheme_and_model + (f"?{rest}" if rest else "")


def _machine(config: StationConfig, bench: SimulatedBench | None, job_folder: Path | None) -> PolishingMachine | None:
    """The simulated PLC's polishing machine, polishing the simulated optic's surface (None: no jobs)."""
    assert config.plc is not None
    table = config.plc.simulator.machine if config.plc.simulator is not None else None
    if table is None and job_folder is None:
        return None
    surface = bench.optic.surface if isinstance(bench, SimulatedInterferometer) else None
    return polishing_machine(config.plc, surface, job_folder)


def start_simulated_station(config: StationConfig, stack: ExitStack, *, name: str,
                            job_folder: Path | None = None) -> SimulatedStation:
    """Build and start every simulator the station's ``sim://`` URLs name; ``stack`` stops them.

    Parameters
    ----------
    config : StationConfig
    stack : ExitStack
    name : str
        The simulated piezo's device name (unique per station).
    job_folder : Path, optional
        Where a simulated PLC's machine reads its jobs (else ``[plc.simulator.machine]``'s or
        ``[plc]``'s folder); with neither the PLC has no machine.

    Raises
    ------
    ConfigError, ValueError
        Simulator settings the simulators refuse, or inconsistent between tables.
    """
    started = SimulatedStation()
    device = None
    if config.camera.simulated:
        if config.station.kind == "shack-hartmann":
            started.bench = _simulated_shack_hartmann(config)
        else:
            started.bench, device = simulated_interferometer(config)
        if isinstance(started.bench.camera, SimulatedGigECamera):
            stack.enter_context(started.bench.camera)
            started.camera_url = started.bench.camera.url
    if config.pzt is not None and config.phase_stepping and config.pzt.url.startswith("sim://"):
        register_serial_simulators()
        if device is None:
            assert config.pzt_simulator is not None
            device = piezo_device(config.pzt_simulator)
        stack.enter_context(attach_simulated_device(name, device))
        started.piezo_url = _piezo_url(config.pzt.url, name)
    if config.plc is not None and config.outputs.enabled and config.plc.link.simulated:
        simulator = PlcSimulator(plc_layout(config.plc), polishing_station(config.plc), port=0,
                                 machine=_machine(config, started.bench, job_folder))
        simulator.start()
        stack.callback(simulator.stop)
        started.plc_simulator = simulator
    return started
