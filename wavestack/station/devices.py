"""Open a station's devices from its configuration: real hardware, or the simulated bench.

``sim://`` URLs make the station build the simulators itself, so nothing has to be launched by
hand: the test optic and the USB3 Vision camera that looks at it (a pyusb backend) -- through an
interferometer, or behind a lenslet array for a Shack-Hartmann station -- the MDT693B
behind ``sim://mdt693b/NAME`` (wired to the camera so the fringes move with its voltage), and the
polishing PLC on a free loopback port. The drivers are the same either way.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.drivers.errors import DeviceDisconnected
from wavestack.drivers.frames import Frame
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration
from wavestack.drivers.plc import CommandLimits, PolishingLink
from wavestack.drivers.genicam.camera_verbs import GenICamCamera
from wavestack.drivers.gige import GigECamera
from wavestack.drivers.u3v import U3VCamera
from wavestack.drivers.usb_tcp import UsbTcpBackend, parse_usbtcp_url
from wavestack.config import BIT_DEPTH, StationConfig, build_calibration, build_piezo, build_simulated_device
from wavestack.simulators import attach_simulated_device, register_serial_simulators
from wavestack.simulators.bench import FrameTruth, SimulatedInterferometer, SimulatedShackHartmann
from wavestack.simulators.optic import TestOptic
from wavestack.simulators.plc import PlcSimulator, PolishingMachine
from wavestack.simulators.spots import SpotRenderer, SpotTruth
from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera
from wavestack.simulators.u3v import U3VSimSettings
from wavestack.station.sim_truth import InterferometerTruthCheck, ShackHartmannTruthCheck
from wavestack.station.truth import TruthCheck

logger = logging.getLogger(__name__)


@dataclass(eq=False)
class StationDevices:
    """The open devices of a station (and the simulators behind them, when simulated).

    Attributes
    ----------
    camera : U3VCamera or GigECamera
    piezo : MDT693B or None
    calibration : PhaseStepCalibration or None
    link : PolishingLink or None
    bench : SimulatedInterferometer or SimulatedShackHartmann or None
        The simulated bench (ground truth), when the camera is simulated.
    plc_simulator : PlcSimulator or None
    truth_check : TruthCheck or None
        Compares results with the simulator's truth, when the camera is simulated.
    """

    camera: U3VCamera | GigECamera
    piezo: MDT693B | None = None
    calibration: PhaseStepCalibration | None = None
    link: PolishingLink | None = None
    bench: SimulatedInterferometer | SimulatedShackHartmann | None = None
    plc_simulator: PlcSimulator | None = None
    truth_check: TruthCheck | None = None

    def truth(self, frame: Frame) -> FrameTruth | SpotTruth | None:
        """The simulator's ground truth of a frame (None on real hardware or when evicted).

        A :class:`FrameTruth` from a simulated interferometer, a :class:`SpotTruth` from a
        simulated Shack-Hartmann camera.
        """
        if self.bench is None:
            return None
        try:
            return self.bench.camera.truth(frame.frame_id)
        except KeyError:
            return None


def configure_camera(camera: GenICamCamera, config: StationConfig) -> None:
    """Apply the configured pixel format, exposure and trigger mode (again after a reopen)."""
    timeout = config.camera.timeout_s
    if config.camera.pixel_format is not None:
        camera.set_pixel_format(config.camera.pixel_format, timeout)
    if config.camera.exposure_us is not None:
        camera.set_exposure_us(config.camera.exposure_us, timeout)
    camera.set_trigger_mode(config.phase_stepping, timeout)


def reconnect_devices(devices: StationDevices, config: StationConfig, *, force_camera: bool = False) -> None:
    """Bring back what a fault took away: reopen a lost camera or piezo and re-apply its configuration.

    The camera is reopened when its connection is lost (or ``force_camera``, after repeated
    failures) and it is on the bus again, then configured; a piezo whose port was lost is opened
    again (echo off, identity and limits read anew) and set to the calibration's bias voltage.
    A device that is still connected is left alone (a timeout or a garbled reply does not need a
    reconnect: the drivers resynchronise on their next exchange).

    Raises
    ------
    DeviceError
        A device is not back yet (the caller backs off and tries again).
    """
    camera = devices.camera
    if not camera.connected or force_camera:
        if not camera.present():
            raise DeviceDisconnected(camera.name, "expected the camera on the bus again; not there yet")
        camera.reopen(timeout_s=config.camera.timeout_s)
        configure_camera(camera, config)
        logger.info("camera %s is back", camera.name)
    piezo, settings = devices.piezo, config.pzt
    if piezo is not None and settings is not None and not piezo.is_open:
        piezo.open(timeout_s=settings.timeout_s)
        if devices.calibration is not None:
            piezo.set_voltage(settings.phase_axis, devices.calibration.bias_v, timeout_s=settings.timeout_s)
        logger.info("piezo %s is back", piezo.name)


def simulated_interferometer(config: StationConfig) -> tuple[SimulatedInterferometer, Any]:
    """The simulated interferometer a ``sim://u3v`` station file describes, and its piezo device (or None).

    Also used by the remote alignment-bench simulator, which serves them from another process.
    """
    sim = config.camera_simulator
    optic_settings = config.optic
    assert optic_settings is not None  # parse_station_config requires [optic] for sim://u3v
    if optic_settings.bit_depth != BIT_DEPTH[sim.pixel_format]:
        raise ValueError(f"{config.source}: [optic] bit_depth {optic_settings.bit_depth} does not match "
                         f"[camera.simulator] pixel_format {sim.pixel_format!r}")
    piezo_device = None
    if config.pzt is not None and config.pzt.url.startswith("sim://"):
        assert config.pzt_simulator is not None
        piezo_device = build_simulated_device(config.pzt_simulator)
    bench = SimulatedInterferometer(TestOptic(optic_settings, sim.height, sim.width), _simulated_camera(config),
                                    piezo_device, config.bench)
    return bench, piezo_device


def _simulated_camera(config: StationConfig) -> U3VSimSettings | GigESimSettings:
    """The simulated camera ``[camera.simulator]`` describes, on the transport ``[camera] url`` names."""
    sim = config.camera_simulator
    if config.camera.transport == "gige":
        return GigESimSettings(serial=sim.serial[:16], width=sim.width, height=sim.height,
                               pixel_format=sim.pixel_format, frame_rate_hz=sim.frame_rate_hz)
    return U3VSimSettings(serial=sim.serial, width=sim.width, height=sim.height, pixel_format=sim.pixel_format,
                          frame_rate_hz=sim.frame_rate_hz, zipped_xml=sim.zipped_xml)


def _simulated_shack_hartmann(config: StationConfig) -> SimulatedShackHartmann:
    sim = config.camera_simulator
    assert config.optic is not None and config.lenslets is not None  # required by parse_station_config
    spots = SpotRenderer(TestOptic(config.optic, sim.height, sim.width), config.lenslets, sim.height, sim.width)
    return SimulatedShackHartmann(spots, _simulated_camera(config))


def _truth_check(bench: SimulatedInterferometer | SimulatedShackHartmann | None,
                 config: StationConfig) -> TruthCheck | None:
    """The comparison with the simulator's truth (simulated cameras only)."""
    if isinstance(bench, SimulatedShackHartmann):
        return ShackHartmannTruthCheck(bench)
    if isinstance(bench, SimulatedInterferometer):
        return InterferometerTruthCheck(bench, config.processing.fit_decimation)
    return None


def _usb_backend(url: str, stack: ExitStack, timeout_s: float) -> UsbTcpBackend | None:
    """The pyusb backend of a camera URL: libusb (None) for ``usb://``, the TCP bus for ``usbtcp://``."""
    if not url.startswith("usbtcp://"):
        return None
    host, port, _ = parse_usbtcp_url(url)
    backend = UsbTcpBackend(host, port, io_timeout_s=timeout_s)
    stack.callback(backend.close)
    return backend


def _open_camera(config: StationConfig, bench: SimulatedInterferometer | SimulatedShackHartmann | None,
                 stack: ExitStack) -> U3VCamera | GigECamera:
    """The station's camera on its transport (a simulated GigE camera is started here, stopped by ``stack``)."""
    settings = config.camera
    if isinstance(bench, (SimulatedInterferometer, SimulatedShackHartmann)) and \
            isinstance(bench.camera, SimulatedGigECamera):
        stack.enter_context(bench.camera)
        return GigECamera.open(bench.camera.url, timeout_s=settings.timeout_s, ring_capacity=settings.ring_capacity)
    if settings.transport == "gige":
        return GigECamera.open(settings.url, timeout_s=settings.timeout_s, ring_capacity=settings.ring_capacity)
    if bench is not None:
        return U3VCamera.open(backend=bench.backend, timeout_s=settings.timeout_s,
                              ring_capacity=settings.ring_capacity)
    return U3VCamera.open(backend=_usb_backend(settings.url, stack, settings.timeout_s), serial=settings.serial,
                          timeout_s=settings.timeout_s, ring_capacity=settings.ring_capacity)


def _piezo_url(url: str, name: str) -> str:
    """``sim://mdt693b`` gets a device name so the station's bench and driver share one device."""
    scheme_and_model, _, rest = url.partition("?")
    if scheme_and_model.count("/") == 2:  # sim://model without a name
        scheme_and_model = f"{scheme_and_model.rstrip('/')}/{name}"
    return scheme_and_model + (f"?{rest}" if rest else "")


def open_station_devices(config: StationConfig, stack: ExitStack, *, job_folder: Path | None = None) -> StationDevices:
    """Open (and, for ``sim://`` URLs, first build) every device; ``stack`` closes them all.

    A simulated PLC gets a polishing machine (``[plc.simulator.machine]``, or its defaults when
    ``job_folder`` is given) that reads its jobs from ``job_folder`` (else the configured folder)
    and polishes the simulated optic's surface, when the optic has one (``[optic.surface]``).

    Raises
    ------
    DeviceError
        A device that does not answer at start, or a PLC whose self-check fails.
    ValueError
        Inconsistent simulator settings.
    """
    timeout = config.camera.timeout_s
    bench: SimulatedInterferometer | SimulatedShackHartmann | None = None
    piezo_device = None
    if config.camera.simulated:
        if config.station.kind == "shack-hartmann":
            bench = _simulated_shack_hartmann(config)
        else:
            bench, piezo_device = simulated_interferometer(config)
    camera = _open_camera(config, bench, stack)
    stack.callback(camera.close)
    configure_camera(camera, config)
    devices = StationDevices(camera=camera, bench=bench, truth_check=_truth_check(bench, config))

    if config.pzt is not None and config.phase_stepping:
        settings = config.pzt
        if settings.url.startswith("sim://"):
            register_serial_simulators()
            name = f"station-{id(devices):x}"
            if piezo_device is None:
                assert config.pzt_simulator is not None
                piezo_device = build_simulated_device(config.pzt_simulator)
            stack.enter_context(attach_simulated_device(name, piezo_device))
            settings = dataclasses.replace(settings, url=_piezo_url(settings.url, name))
        piezo = build_piezo(settings)
        stack.callback(piezo.close)
        piezo.open(timeout_s=settings.timeout_s)
        devices.piezo = piezo
        devices.calibration = build_calibration(settings)

    if config.plc is not None and config.outputs.enabled:
        link_settings = config.plc.link
        host, port = link_settings.host, link_settings.port
        if link_settings.simulated:
            simulator = PlcSimulator(config.plc.sim_layout(), config.plc.polishing_station(), port=0,
                                     machine=_simulated_machine(config, bench, job_folder))
            simulator.start()
            stack.callback(simulator.stop)
            host, port = simulator.host, simulator.port
            devices.plc_simulator = simulator
        link = PolishingLink(host, port, link_settings.register_map(), link_settings.link_timing(),
                             command_limits=CommandLimits(config.outputs.max_removal_nm, config.outputs.max_step_nm),
                             job_limits=link_settings.job_limits())
        stack.callback(link.close)
        link.connect(timeout_s=max(timeout, link_settings.io_timeout_s * 4))
        link.self_check(timeout_s=max(timeout, link_settings.io_timeout_s * 4))
        devices.link = link
    return devices


def _simulated_machine(config: StationConfig, bench: SimulatedInterferometer | SimulatedShackHartmann | None,
                       job_folder: Path | None) -> PolishingMachine | None:
    """The simulated PLC's polishing machine, polishing the simulated optic's surface (None: no jobs)."""
    assert config.plc is not None
    table = config.plc.simulator.machine if config.plc.simulator is not None else None
    if table is None and job_folder is None:
        return None
    surface = bench.optic.surface if isinstance(bench, SimulatedInterferometer) else None
    return config.plc.polishing_machine(surface, job_folder)


def phase_steps_rad(config: StationConfig) -> tuple[float, ...]:
    """The configured phase steps in radians."""
    return tuple(math.radians(step) for step in config.processing.steps_deg)
