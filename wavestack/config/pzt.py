"""Configuration of the piezo phase shifter: tables ``[pzt]`` and ``[pzt.simulator]``.

``[pzt]`` configures the station's driver and the phase-step calibration; ``[pzt.simulator]``
describes the simulated controller that ``wavestack sim pzt`` serves on a pseudo-terminal (and that
a station attaches by name for ``sim://mdt693b/NAME`` URLs; an unnamed ``sim://`` URL takes its
personality from the URL query). Other top-level tables of the file are left to their own loaders,
so one station file can hold every instrument.

Example (see ``config/pzt-sim.toml`` and ``config/pzt-mdt693b.example.toml``)::

    [pzt]
    url = "/dev/ttyUSB0"
    axes = ["x"]
    volts_per_radian = 0.5
    bias_v = 40.0

    [pzt.simulator]
    prompt = ">"
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from wavestack.config.schema import ConfigError, device_tables, load_toml, parse_section, setting
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration

Axis = Literal["x", "y", "z"]


@dataclass(frozen=True)
class PiezoSettings:
    """``[pzt]``: the piezo controller the station drives and the phase-step calibration."""

    url: str = setting(url_kinds=("sim", "socket", "device"),
                       doc="serial port: /dev/ttyUSB0, /dev/serial/by-id/..., COM3, "
                           "socket://host:port or sim://mdt693b")
    volts_per_radian: float = setting(minimum=-150.0, maximum=150.0,
                                      doc="phase-step calibration, V per radian (nonzero)")
    bias_v: float = setting(minimum=0.0, maximum=150.0, doc="voltage at zero phase step, V")
    axes: tuple[Axis, ...] = setting(("x",), doc="driven axes, e.g. [\"x\"]; an MDT694B has only x")
    phase_axis: Axis = setting("x", doc="axis that moves the reference mirror (one of axes)")
    software_min_v: float = setting(0.0, minimum=0.0, maximum=150.0, doc="software lower limit, V")
    software_max_v: float = setting(150.0, minimum=0.0, maximum=150.0, doc="software upper limit, V")
    readback_tolerance_v: float = setting(0.5, minimum=0.01, maximum=10.0,
                                          doc="largest accepted |read-back - command|, V")
    timeout_s: float = setting(1.0, minimum=0.01, maximum=60.0, doc="per-exchange timeout, s")
    settle_s: float = setting(0.05, minimum=0.0, maximum=10.0, doc="wait after each phase step, s")
    command_set: Literal["auto", "mdt693b", "mdt693a"] = setting(
        "auto", doc="auto: detected at open; mdt693b; mdt693a (an MDT693A, or a B unit in its A mode)")


@dataclass(frozen=True)
class PiezoSimulatorSettings:
    """``[pzt.simulator]``: personality of the simulated controller (its ``id?`` reply and settings)."""

    model: Literal["MDT693B", "MDT694B", "MDT693A"] = setting(
        "MDT693B", doc="MDT693B (x, y, z), MDT694B (x) or MDT693A (x, y, z; single-letter commands only)")
    echo: bool = setting(True, doc="echo at power-on")
    prompt: Literal[">", "*"] = setting(">", doc="'>' (firmware 1.10) or '*' (firmware 1.05)")
    firmware: str = setting("1.10", doc="firmware version in the id? reply")
    serial_number: str = setting("SIM-000001", doc="serial number in the id? reply")
    vlimit_v: float = setting(150.0, choices=(75.0, 100.0, 150.0), doc="front-panel limit switch, V")
    compatibility_mode: bool = setting(False, doc="a B unit powered up in its MDT693A compatibility mode (cm=1)")


def parse_pzt_config(document: Mapping[str, Any], *, source: str) -> tuple[PiezoSettings, PiezoSimulatorSettings]:
    """Build the settings from a parsed TOML document (a mapping holding table ``pzt``).

    Raises
    ------
    ConfigError
        Missing ``[pzt]``, any key error :func:`wavestack.config.parse_section` reports, or
        inconsistent values (software_min_v >= software_max_v, repeated axes, phase_axis not driven,
        zero volts_per_radian); each message names ``source`` and the key.
    """
    main, simulator_table = device_tables(document, "pzt", what="the piezo controller settings", source=source)
    settings = parse_section(PiezoSettings, main, source=source, section="pzt")
    simulator = parse_section(PiezoSimulatorSettings, simulator_table or {}, source=source,
                              section="pzt.simulator")
    where = f"{source}: [pzt]"
    if settings.software_min_v >= settings.software_max_v:
        raise ConfigError(f"{where} software_min_v: expected < software_max_v ({settings.software_max_v:g}), "
                          f"got {settings.software_min_v:g}")
    if not settings.axes or len(set(settings.axes)) != len(settings.axes):
        raise ConfigError(f"{where} axes: expected distinct axes from x, y, z, got {list(settings.axes)}")
    if settings.phase_axis not in settings.axes:
        raise ConfigError(f"{where} phase_axis: expected one of axes {list(settings.axes)}, "
                          f"got {settings.phase_axis!r}")
    if settings.volts_per_radian == 0.0:
        raise ConfigError(f"{where} volts_per_radian: expected a nonzero calibration, got 0")
    return settings, simulator


def load_pzt_config(path: str | Path) -> tuple[PiezoSettings, PiezoSimulatorSettings]:
    """Read ``[pzt]`` and ``[pzt.simulator]`` from a TOML file (see :func:`parse_pzt_config`)."""
    return parse_pzt_config(load_toml(path), source=str(path))


def build_piezo(settings: PiezoSettings) -> MDT693B:
    """The driver the settings describe (not yet opened)."""
    return MDT693B(settings.url, axes=settings.axes, software_min_v=settings.software_min_v,
                   software_max_v=settings.software_max_v, readback_tolerance_v=settings.readback_tolerance_v,
                   timeout_s=settings.timeout_s, command_set=settings.command_set)


def build_calibration(settings: PiezoSettings) -> PhaseStepCalibration:
    """The phase-step calibration the settings describe."""
    return PhaseStepCalibration(volts_per_radian=settings.volts_per_radian, bias_v=settings.bias_v)
