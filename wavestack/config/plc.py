"""Configuration of the polishing-station PLC link and of its simulator (TOML ``[plc]``).

One file describes both ends: ``[plc]`` holds what the driver needs (address, unit id, register
map, float32 byte orders, function codes, timing, the job folder and the job limits) and what the
PLC is configured with (watchdog timeout); ``[plc.simulator.polishing]`` holds the display model the
commands are shown on, ``[plc.simulator.machine]`` (optional) the simulated polishing machine that
runs jobs: its job folder, speed, its own tool and its own limits. ``config/plc-sim.toml``
is the simulator's file and equals the built-in defaults; ``config/plc-example.toml`` is a commented
example for a real PLC.

This module declares the settings and turns the link's into the driver's :class:`RegisterMap` and
:class:`LinkTiming`; the simulator starter (``wavestack.simulated``) turns the same settings into
the simulator's own layout, display model and machine.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from wavestack.config.schema import ConfigError, device_tables, load_toml, parse_section, setting
from wavestack.drivers.plc.jobs import JobLimits
from wavestack.drivers.plc.register_map import RegisterMap
from wavestack.drivers.plc.transport import LinkTiming

__all__ = ["MachineModelSettings", "PlcConfig", "PlcLinkSettings", "PlcSimulatorSettings", "PolishingModelSettings",
           "load_plc_config", "parse_plc_config"]

WordOrderName = Literal["ABCD", "CDAB", "BADC", "DCBA"]

_TCP_URL = re.compile(r"^tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[^:/\s\[\]]+):(?P<port>\d{1,5})/?$")
#: A 15-term (Noll 1..15) starting surface, nm: astigmatism, coma, spherical and friends.
DEFAULT_SURFACE_NM = (0.0, 0.0, 0.0, 120.0, -45.0, 30.0, 60.0, -25.0, 18.0, 12.0, -9.0, 40.0, 6.0, -5.0, 4.0)


@dataclass(frozen=True)
class PlcLinkSettings:
    """``[plc]``: where the PLC is, its register map, byte orders, function codes and timing."""

    url: str = setting("tcp://127.0.0.1:5020", url_kinds=("tcp", "sim"),
                       doc="Modbus/TCP address, tcp://HOST:PORT; sim://plc: a station starts the simulator")
    unit_id: int = setting(1, minimum=0, maximum=255, doc="Modbus unit (slave) id")
    word_order: WordOrderName = setting("CDAB", doc="float32 byte order of every block: ABCD, CDAB, BADC, DCBA")
    self_check_word_order: WordOrderName | None = setting(None, doc="byte order of the self-check constant")
    command_word_order: WordOrderName | None = setting(None, doc="byte order of the command block's floats")
    output_word_order: WordOrderName | None = setting(None, doc="byte order of the output block's floats")
    self_check_register: int = setting(0, minimum=0, maximum=65534, doc="first of 2 registers: float32 constant")
    self_check_value: float = setting(12345.678, doc="the constant the self-check must read")
    heartbeat_register: int = setting(10, minimum=0, maximum=65535, doc="host increments it every cycle")
    rearm_register: int = setting(11, minimum=0, maximum=65535, doc="write 1 to re-arm the watchdog")
    status_register: int = setting(20, minimum=0, maximum=65533,
                                   doc="first of 3 registers: status word, last accepted id, heartbeat echo")
    command_block: tuple[int, int] = setting((100, 32), minimum=0, maximum=65535,
                                             doc="[start, count], count = 2 + 2 x terms")
    output_block: tuple[int, int] = setting((200, 32), minimum=0, maximum=65535,
                                            doc="[start, count], read-only machine outputs")
    read_function_code: Literal[3, 4] = setting(3, doc="3 holding or 4 input registers")
    single_write_function_code: Literal[6, 16] = setting(6, doc="heartbeat and re-arm writes")
    command_write_function_code: Literal[16] = setting(16, doc="command block writes")
    watchdog_timeout_s: float = setting(2.0, minimum=0.01, maximum=600.0, doc="PLC watchdog timeout")
    io_timeout_s: float = setting(0.5, minimum=0.001, maximum=60.0, doc="longest wait for one reply")
    reconnect_initial_s: float = setting(0.05, minimum=0.001, maximum=60.0, doc="first reconnect back-off")
    reconnect_max_s: float = setting(0.5, minimum=0.001, maximum=600.0,
                                     doc="longest reconnect back-off; at most a quarter of watchdog_timeout_s")
    command_retries: int = setting(2, minimum=0, maximum=10, doc="resends of a command after a lost reply")
    heartbeat_echo_max_lag: int = setting(2, minimum=0, maximum=1000, doc="beats the echo may trail")
    job_register: int | None = setting(300, minimum=0, maximum=65528,
                                       doc="first of 8 registers: job action, id, CRC-32, points, total dwell")
    machine_register: int | None = setting(320, minimum=0, maximum=65529,
                                           doc="first of 7 read-only registers: state, reason, job id, progress")
    owner_register: int | None = setting(12, minimum=0, maximum=65532,
                                         doc="first of 4 registers: the host's ownership token (FC16, whole)")
    display_register: int | None = setting(340, minimum=0, maximum=65528,
                                           doc="first of 8 registers: each result for the machine's panel (FC16, whole)")
    job_folder: str | None = setting(None, doc="where the host writes job files (the machine's share)")
    job_key_file: str | None = setting(None, doc="a file holding the job key (hex): job files carry their "
                                                 "HMAC-SHA256 and the machine runs only those; relative to this file")
    job_max_points: int = setting(500_000, minimum=1, maximum=2**32 - 1, doc="most points in one job")
    job_max_total_dwell_s: float = setting(36_000.0, minimum=0.001, maximum=1e7, doc="longest total dwell, s")
    job_max_dwell_per_point_s: float = setting(60.0, minimum=0.001, maximum=1e5, doc="longest dwell at a point")
    job_max_feed_mm_s: float = setting(100.0, minimum=0.001, maximum=1e4, doc="fastest feed between points")
    job_travel_x_mm: tuple[float, float] = setting((-100.0, 100.0), doc="[lo, hi] machine travel in x, mm")
    job_travel_y_mm: tuple[float, float] = setting((-100.0, 100.0), doc="[lo, hi] machine travel in y, mm")

    @property
    def simulated(self) -> bool:
        """True for ``sim://plc``: the station runs the simulator itself on a free loopback port."""
        return self.url.startswith("sim://")

    @property
    def host(self) -> str:
        """Host part of :attr:`url`."""
        return _split_url(self.url)[0]

    @property
    def port(self) -> int:
        """Port part of :attr:`url`."""
        return _split_url(self.url)[1]

    @property
    def n_terms(self) -> int:
        """Removal terms the command block carries."""
        return (self.command_block[1] - 2) // 2

    def register_map(self) -> RegisterMap:
        """The driver's register map (raises ValueError for an inconsistent map)."""
        return RegisterMap.build(
            unit_id=self.unit_id, word_order=self.word_order, self_check_register=self.self_check_register,
            self_check_value=self.self_check_value, heartbeat_register=self.heartbeat_register,
            rearm_register=self.rearm_register, status_register=self.status_register,
            command_block=self.command_block, output_block=self.output_block,
            read_function=self.read_function_code, single_write_function=self.single_write_function_code,
            block_write_function=self.command_write_function_code,
            self_check_word_order=self.self_check_word_order, command_word_order=self.command_word_order,
            output_word_order=self.output_word_order, job_register=self.job_register,
            machine_register=self.machine_register, owner_register=self.owner_register,
            display_register=self.display_register)

    def job_limits(self) -> JobLimits:
        """The host's job limits (raises ValueError for an empty travel)."""
        return JobLimits(self.job_max_points, self.job_max_total_dwell_s, self.job_max_dwell_per_point_s,
                         self.job_max_feed_mm_s, self.job_travel_x_mm, self.job_travel_y_mm)

    def link_timing(self) -> LinkTiming:
        """The driver's timing and retry policy."""
        return LinkTiming(io_timeout_s=self.io_timeout_s, reconnect_initial_s=self.reconnect_initial_s,
                          reconnect_max_s=self.reconnect_max_s, command_retries=self.command_retries,
                          heartbeat_echo_max_lag=self.heartbeat_echo_max_lag)


@dataclass(frozen=True)
class PolishingModelSettings:
    """``[plc.simulator.polishing]``: the simulated machine (see ``simulators/plc/polishing.py``)."""

    initial_surface_nm: tuple[float, ...] = setting(DEFAULT_SURFACE_NM,
                                                    doc="starting Zernike coefficients (Noll 1..n), nm")
    efficiency: float = setting(0.8, minimum=0.001, maximum=1.0, doc="mean fraction of the commanded removal")
    efficiency_spread: float = setting(0.05, minimum=0.0, maximum=0.99, doc="relative per-term scatter")
    noise_nm: float = setting(0.5, minimum=0.0, maximum=1000.0, doc="process noise per term and pass, nm")
    max_removal_nm: float = setting(500.0, minimum=0.001, maximum=1e6, doc="largest |removal| per term, nm")
    seed: int = setting(0, minimum=0, doc="random seed of the model")
    pass_duration_s: float = setting(0.0, minimum=0.0, maximum=3600.0, doc="time one pass keeps the PLC busy")


@dataclass(frozen=True)
class MachineModelSettings:
    """``[plc.simulator.machine]``: the simulated polishing machine (see ``simulators/plc/machine.py``)."""

    job_folder: str | None = setting(None, doc="the machine's job folder; none: [plc] job_folder")
    time_scale: float = setting(100.0, minimum=0.001, maximum=1e9, doc="simulated seconds per real second")
    tif_fwhm_mm: float = setting(3.0, minimum=0.001, maximum=1000.0, doc="the tool's nominal FWHM, mm")
    tif_peak_rate_nm_s: float = setting(10.0, minimum=0.0, maximum=1e6, doc="the tool's nominal peak rate, nm/s")
    width_error: float = setting(0.0, minimum=-0.9, maximum=1.0, doc="real FWHM / nominal - 1")
    rate_error: float = setting(0.0, minimum=-0.9, maximum=1.0, doc="real peak rate / nominal - 1")
    efficiency_spread: float = setting(0.0, minimum=0.0, maximum=0.99, doc="per-point efficiency half-width")
    noise_nm: float = setting(0.0, minimum=0.0, maximum=1000.0, doc="process noise a job leaves per pixel, nm")
    seed: int = setting(0, minimum=0, doc="random seed of the machine")
    max_points: int = setting(500_000, minimum=1, maximum=2**32 - 1, doc="the machine's own point limit")
    max_total_dwell_s: float = setting(36_000.0, minimum=0.001, maximum=1e7, doc="its total dwell limit, s")
    max_dwell_per_point_s: float = setting(60.0, minimum=0.001, maximum=1e5, doc="its per-point dwell limit, s")
    max_feed_mm_s: float = setting(100.0, minimum=0.001, maximum=1e4, doc="its feed limit, mm/s")
    travel_x_mm: tuple[float, float] = setting((-100.0, 100.0), doc="its travel in x, mm")
    travel_y_mm: tuple[float, float] = setting((-100.0, 100.0), doc="its travel in y, mm")


@dataclass(frozen=True)
class PlcSimulatorSettings:
    """``[plc.simulator]``: what only the simulator needs."""

    polishing: PolishingModelSettings = PolishingModelSettings()
    machine: MachineModelSettings | None = None


@dataclass(frozen=True)
class PlcConfig:
    """A checked PLC configuration.

    Attributes
    ----------
    link
        The ``[plc]`` table.
    simulator
        The ``[plc.simulator]`` table, None when the file has none (a real PLC).
    source
        The file it came from, or ``"built-in defaults"``.
    """

    link: PlcLinkSettings
    simulator: PlcSimulatorSettings | None
    source: str

    def job_key_path(self) -> Path | None:
        """``[plc] job_key_file``, relative to the configuration's folder (None: no job key)."""
        if self.link.job_key_file is None:
            return None
        path = Path(self.link.job_key_file).expanduser()
        return path if path.is_absolute() or self.source == "built-in defaults" else Path(self.source).parent / path


def parse_plc_config(document: Mapping[str, Any], *, source: str) -> PlcConfig:
    """Build and check a :class:`PlcConfig` from a parsed TOML document holding table ``plc``.

    Raises
    ------
    ConfigError
        As :func:`load_plc_config`.
    """
    link_table, simulator_table = device_tables(document, "plc", what="the PLC link", source=source)
    link = parse_section(PlcLinkSettings, link_table, source=source, section="plc")
    simulator = (None if simulator_table is None else
                 parse_section(PlcSimulatorSettings, simulator_table, source=source, section="plc.simulator"))
    config = PlcConfig(link, simulator, source)
    _check_consistency(config)
    return config


def load_plc_config(path: str | Path | None) -> PlcConfig:
    """Read and check the ``[plc]`` table of a TOML file (None: the built-in simulator defaults).

    Other top-level tables are ignored, so one station file can hold every device.

    Raises
    ------
    ConfigError
        A missing file or ``[plc]`` table, unknown keys, wrong types or ranges, a URL that is not
        ``tcp://HOST:PORT``, an inconsistent register map (overlaps, counts, function codes) or an
        initial surface whose length differs from the command block's number of terms.
    """
    if path is None:
        config = PlcConfig(PlcLinkSettings(), PlcSimulatorSettings(), "built-in defaults")
        _check_consistency(config)
        return config
    return parse_plc_config(load_toml(path), source=str(path))


def _split_url(url: str) -> tuple[str, int]:
    if url == "sim://plc":
        return "127.0.0.1", 0  # the simulator picks a free port
    match = _TCP_URL.match(url)
    if match is None:
        raise ValueError(f"expected tcp://HOST:PORT, got {url!r}")
    port = int(match.group("port"))
    if not 1 <= port <= 65535:
        raise ValueError(f"port must be 1..65535 in {url!r}")
    return match.group("host").strip("[]"), port


def _check_consistency(config: PlcConfig) -> None:
    link, where = config.link, f"{config.source}: [plc]"
    try:
        _split_url(link.url)
    except ValueError as error:
        raise ConfigError(f"{where} url: {error}") from None
    try:
        link.register_map()
    except ValueError as error:
        raise ConfigError(f"{where} register map: {error}") from None
    try:
        link.job_limits()
    except ValueError as error:
        raise ConfigError(f"{where} job limits: {error}") from None
    model = config.simulator.machine if config.simulator is not None else None
    for name in ("travel_x_mm", "travel_y_mm"):
        span = getattr(model, name) if model is not None else (0.0, 1.0)
        if not span[0] < span[1]:
            raise ConfigError(f"{config.source}: [plc.simulator.machine] {name}: expected [lo, hi] with lo < hi, "
                              f"got {list(span)}")
    if model is not None and link.job_register is None:
        raise ConfigError(f"{config.source}: [plc.simulator.machine] needs the job blocks ([plc] job_register and "
                          "machine_register)")
    if link.reconnect_initial_s > link.reconnect_max_s:
        raise ConfigError(f"{where} reconnect_initial_s ({link.reconnect_initial_s}) must not exceed "
                          f"reconnect_max_s ({link.reconnect_max_s})")
    if link.reconnect_max_s > link.watchdog_timeout_s / 4:
        # a PLC back from a short outage must get a heartbeat before its watchdog runs out
        raise ConfigError(f"{where} reconnect_max_s = {link.reconnect_max_s:g}: expected at most a quarter of "
                          f"watchdog_timeout_s ({link.watchdog_timeout_s:g} s), or after a short PLC outage the "
                          "host's back-off alone outlasts the watchdog")
    problem = _self_check_problem(link.self_check_value)
    if problem is not None:
        raise ConfigError(f"{where} self_check_value = {link.self_check_value!r}: {problem}")
    longest_command_s = link.io_timeout_s * (1 + link.command_retries)
    if not longest_command_s < link.watchdog_timeout_s:
        raise ConfigError(f"{where} io_timeout_s ({link.io_timeout_s:g}) x (1 + command_retries {link.command_retries}) "
                          f"= {longest_command_s:g} s: expected less than watchdog_timeout_s "
                          f"({link.watchdog_timeout_s:g}), or one retried command starves the watchdog")
    if link.simulated and config.simulator is None:
        raise ConfigError(f"{where} url: sim://plc needs a [plc.simulator] table (the simulated machine)")
    if config.simulator is not None:
        surface = config.simulator.polishing.initial_surface_nm
        if len(surface) != link.n_terms:
            raise ConfigError(f"{config.source}: [plc.simulator.polishing] initial_surface_nm: expected "
                              f"{link.n_terms} terms (command_block count {link.command_block[1]} = 2 + 2 x terms), "
                              f"got {len(surface)}")


_FLOAT32_MAX = 3.4028234663852886e38


def _self_check_problem(value: float) -> str | None:
    """Why ``value`` cannot serve as the self-check constant, or None.

    The start-up self-check reads the constant back to prove the word order; it must be a
    finite nonzero float32 whose four byte orders (ABCD, CDAB, BADC, DCBA) are four different
    register pairs, or a PLC with cleared memory, or the wrong order, would pass.
    """
    if not abs(value) <= _FLOAT32_MAX:
        return f"expected a float32 (|value| <= {_FLOAT32_MAX:.7g})"
    a, b, c, d = struct.pack(">f", value)
    if len({(a, b, c, d), (c, d, a, b), (b, a, d, c), (d, c, b, a)}) != 4 or value == 0.0:
        return "expected a nonzero constant whose four byte orders differ (e.g. 12345.678), so the check can tell them"
    return None
