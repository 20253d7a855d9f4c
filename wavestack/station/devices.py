"""Open a station's devices from its configuration: real hardware, or the simulated bench.

``sim://`` URLs make the station start the simulators first, through the simulator starter
(:func:`wavestack.simulated.start_simulated_station`: the test optic and the USB3 Vision camera
that looks at it, the MDT693B behind ``sim://mdt693b/NAME``, the polishing PLC on a free loopback
port), which this module imports only then: a real bench never loads a simulator. The drivers are
the same either way.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.config import StationConfig, build_calibration, build_piezo
from wavestack.drivers.errors import DeviceDisconnected
from wavestack.drivers.frames import Frame
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration
from wavestack.drivers.genicam.camera_verbs import GenICamCamera
from wavestack.drivers.gige import GigECamera
from wavestack.drivers.plc import CommandLimits, PolishingLink
from wavestack.drivers.u3v import U3VCamera
from wavestack.drivers.usb_tcp import UsbTcpBackend, parse_usbtcp_url
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
    bench : object or None
        The simulated bench (``wavestack.simulators``' interferometer or Shack-Hartmann bench: the
        ground truth), when the camera is simulated.
    plc_simulator : object or None
        The running PLC simulator, when the PLC is simulated.
    truth_check : TruthCheck or None
        Compares results with the simulator's truth, when the camera is simulated.
    """

    camera: U3VCamera | GigECamera
    piezo: MDT693B | None = None
    calibration: PhaseStepCalibration | None = None
    link: PolishingLink | None = None
    bench: Any = None
    plc_simulator: Any = None
    truth_check: TruthCheck | None = None

    def truth(self, frame: Frame) -> Any:
        """The simulator's ground truth of a frame (None on real hardware or when evicted).

        The simulated interferometer's frame truth, or the simulated Shack-Hartmann camera's
        spot truth.
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


def _usb_backend(url: str, stack: ExitStack, timeout_s: float) -> UsbTcpBackend | None:
    """The pyusb backend of a camera URL: libusb (None) for ``usb://``, the TCP bus for ``usbtcp://``."""
    if not url.startswith("usbtcp://"):
        return None
    host, port, _ = parse_usbtcp_url(url)
    backend = UsbTcpBackend(host, port, io_timeout_s=timeout_s)
    stack.callback(backend.close)
    return backend


def open_station_devices(config: StationConfig, stack: ExitStack, *, job_folder: Path | None = None) -> StationDevices:
    """Open (and, for ``sim://`` URLs, first start) every device; ``stack`` closes them all.

    A simulated PLC gets a polishing machine (``[plc.simulator.machine]``, or its defaults when
    ``job_folder`` is given) that reads its jobs from ``job_folder`` (else the configured folder)
    and polishes the simulated optic's surface, when the optic has one (``[optic.surface]``).

    Raises
    ------
    DeviceError
        A device that does not answer at start, or a PLC whose self-check fails.
    ConfigError, ValueError
        Simulator settings the simulators refuse.
    """
    timeout = config.camera.timeout_s
    devices = StationDevices(camera=None)  # type: ignore[arg-type]  # the camera is opened next
    simulated = None
    if _any_simulated(config):
        from wavestack.simulated import start_simulated_station  # the simulator starter, for sim:// only

        simulated = start_simulated_station(config, stack, name=f"station-{id(devices):x}", job_folder=job_folder)
        devices.bench, devices.plc_simulator = simulated.bench, simulated.plc_simulator
    if devices.bench is not None:
        devices.truth_check = _truth_check(devices.bench, config)
    camera = _open_camera(config, simulated, stack)
    stack.callback(camera.close)
    configure_camera(camera, config)
    devices.camera = camera

    if config.pzt is not None and config.phase_stepping:
        settings = config.pzt
        if simulated is not None and simulated.piezo_url is not None:
            settings = dataclasses.replace(settings, url=simulated.piezo_url)
        piezo = build_piezo(settings)
        stack.callback(piezo.close)
        piezo.open(timeout_s=settings.timeout_s)
        devices.piezo = piezo
        devices.calibration = build_calibration(settings)

    if config.plc is not None and config.outputs.enabled:
        link_settings = config.plc.link
        host, port = link_settings.host, link_settings.port
        if devices.plc_simulator is not None:
            host, port = devices.plc_simulator.host, devices.plc_simulator.port
        link = PolishingLink(host, port, link_settings.register_map(), link_settings.link_timing(),
                             command_limits=CommandLimits(config.outputs.max_removal_nm, config.outputs.max_step_nm),
                             job_limits=link_settings.job_limits())
        stack.callback(link.close)
        link.connect(timeout_s=max(timeout, link_settings.io_timeout_s * 4))
        link.self_check(timeout_s=max(timeout, link_settings.io_timeout_s * 4))
        devices.link = link
    return devices


def _open_camera(config: StationConfig, simulated: Any, stack: ExitStack) -> U3VCamera | GigECamera:
    """The station's camera on its transport: the simulated bench's (GigE on loopback, or its USB backend), or hardware."""
    settings = config.camera
    if simulated is not None and simulated.camera_url is not None:
        return GigECamera.open(simulated.camera_url, timeout_s=settings.timeout_s, ring_capacity=settings.ring_capacity)
    if settings.transport == "gige":
        return GigECamera.open(settings.url, timeout_s=settings.timeout_s, ring_capacity=settings.ring_capacity)
    if simulated is not None and simulated.bench is not None:
        return U3VCamera.open(backend=simulated.bench.backend, timeout_s=settings.timeout_s,
                              ring_capacity=settings.ring_capacity)
    return U3VCamera.open(backend=_usb_backend(settings.url, stack, settings.timeout_s), serial=settings.serial,
                          timeout_s=settings.timeout_s, ring_capacity=settings.ring_capacity)


def _any_simulated(config: StationConfig) -> bool:
    """True when a configured URL names a simulated device (``sim://``)."""
    return (config.camera.simulated or (config.pzt is not None and config.pzt.url.startswith("sim://"))
            or (config.plc is not None and config.plc.link.simulated))


def _truth_check(bench: Any, config: StationConfig) -> TruthCheck:
    """The comparison with a simulated camera's truth (:mod:`~wavestack.station.sim_truth`, which reads it)."""
    from wavestack.station.sim_truth import InterferometerTruthCheck, ShackHartmannTruthCheck  # sim:// only

    if config.station.kind == "shack-hartmann":
        return ShackHartmannTruthCheck(bench)
    return InterferometerTruthCheck(bench, config.processing.fit_decimation)


def phase_steps_rad(config: StationConfig) -> tuple[float, ...]:
    """The configured phase steps in radians."""
    return tuple(math.radians(step) for step in config.processing.steps_deg)
