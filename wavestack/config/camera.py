"""Configuration of the camera: tables ``[camera]`` and ``[camera.simulator]``.

``[camera]`` configures the driver: ``url = "usb://"`` opens the first USB3 Vision camera,
``usb://SERIAL`` one by serial number, ``sim://u3v`` the simulated camera of a simulated
bench (a pyusb backend the station builds itself, see :mod:`wavestack.simulators.bench`), and
``usbtcp://HOST:PORT[/SERIAL]`` a camera whose USB bus is served over TCP by another process
(:mod:`wavestack.drivers.usb_tcp`: the remote alignment-bench simulator's camera).
``gige://ADDRESS[:PORT]`` opens a GigE Vision camera by its address, ``gige://SERIAL`` by the
serial its DISCOVERY reports (``?via=HOST[:PORT]`` asks one address instead of broadcasting), and
``sim://gige`` the simulated bench's camera as a GigE Vision camera on loopback.
``[camera.simulator]`` describes that simulated camera. Example::

    [camera]
    url = "usb://"
    pixel_format = "Mono12"
    exposure_us = 2000.0
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from wavestack.config.schema import ConfigError, device_tables, parse_section, setting
from wavestack.drivers.gige.discovery import parse_gige_url
from wavestack.drivers.usb_tcp import parse_usbtcp_url

PixelFormat = Literal["Mono8", "Mono12", "Mono16"]


@dataclass(frozen=True)
class CameraSettings:
    """``[camera]``: which camera and how to set it up."""

    url: str = setting("sim://u3v", url_kinds=("usb", "sim", "usbtcp", "gige"),
                       doc="usb:// (first camera), usb://SERIAL, sim://u3v or sim://gige (simulated bench), "
                           "usbtcp://HOST:PORT[/SERIAL] (a USB bus served over TCP), gige://ADDRESS[:PORT] or "
                           "gige://SERIAL (GigE Vision)")
    pixel_format: PixelFormat | None = setting(None, doc="set at start; absent keeps the camera's")
    exposure_us: float | None = setting(None, minimum=1.0, maximum=10_000_000.0, doc="exposure, microseconds")
    timeout_s: float = setting(2.0, minimum=0.01, maximum=60.0, doc="open and per-frame timeout, s")
    ring_capacity: int = setting(4, minimum=1, maximum=256, doc="frames held between stream and pipeline")

    @property
    def serial(self) -> str | None:
        """Serial number from ``usb://SERIAL`` or ``usbtcp://HOST:PORT/SERIAL`` (None for ``usb://`` or a
        simulator)."""
        if self.url.startswith("usbtcp://"):
            return self.url[len("usbtcp://"):].partition("/")[2].strip("/") or None
        if not self.url.startswith("usb://"):
            return None
        return self.url[len("usb://"):] or None

    @property
    def simulated(self) -> bool:
        return self.url.startswith("sim://")

    @property
    def transport(self) -> Literal["u3v", "gige"]:
        """``"gige"`` for GigE Vision (``gige://``, ``sim://gige``), ``"u3v"`` for USB3 Vision."""
        return "gige" if self.url.startswith("gige://") or self.url == "sim://gige" else "u3v"


@dataclass(frozen=True)
class CameraSimulatorSettings:
    """``[camera.simulator]``: the simulated camera's power-on state."""

    width: int = setting(1024, minimum=16, maximum=8192)
    height: int = setting(1024, minimum=16, maximum=8192)
    pixel_format: PixelFormat = "Mono12"
    frame_rate_hz: float = setting(30.0, minimum=0.1, maximum=1000.0)
    serial: str = "WS-SIM-0001"
    zipped_xml: bool = False


def parse_camera_config(document: Mapping[str, Any], *, source: str) -> tuple[CameraSettings, CameraSimulatorSettings]:
    """Build the camera settings from a parsed TOML document holding table ``camera``.

    Raises
    ------
    ConfigError
        Missing ``[camera]`` or any key error; the message names ``source`` and the key.
    """
    main, simulator_table = device_tables(document, "camera", what="the camera settings", source=source)
    settings = parse_section(CameraSettings, main, source=source, section="camera")
    simulator = parse_section(CameraSimulatorSettings, simulator_table or {}, source=source,
                              section="camera.simulator")
    if settings.url.startswith("usbtcp://"):
        try:
            parse_usbtcp_url(settings.url)
        except ValueError as error:
            raise ConfigError(f"{source}: [camera] {error}") from None
    if settings.url.startswith("gige://"):
        try:
            parse_gige_url(settings.url)
        except ValueError as error:
            raise ConfigError(f"{source}: [camera] {error}") from None
    if settings.simulated and settings.url not in ("sim://u3v", "sim://gige"):
        raise ConfigError(f"{source}: [camera] url: expected sim://u3v or sim://gige for the simulated camera, "
                          f"got {settings.url!r}")
    return settings, simulator
