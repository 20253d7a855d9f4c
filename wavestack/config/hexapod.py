"""Configuration of a PI GCS 2.0 platform: table ``[hexapod]`` (and the same schema for a field stage).

``[hexapod]`` configures the driver (:class:`~wavestack.drivers.pi_gcs.PIHexapod`): where the
controller is, which axes it moves, the soft limits and the largest step per move of every axis,
the exchange timeout, and optionally the pivot point and platform velocity set at start-up. The
simulator's table ``[hexapod.simulator]`` is split off here and left to the simulator's own
loader. The bench's two-axis field stage uses the same schema under another table name
(``parse_hexapod_config(document, source=..., table="field_stage")``).

Example (see ``config/hexapod-sim.toml``)::

    [hexapod]
    url = "tcp://192.168.0.20"          # port 50000 when absent
    axes = ["X", "Y", "Z", "U", "V", "W"]
    soft_lower = [-5.0, -5.0, -2.0, -0.5, -0.5, -0.5]
    soft_upper = [5.0, 5.0, 2.0, 0.5, 0.5, 0.5]
    max_step = [0.5, 0.5, 0.5, 0.05, 0.05, 0.05]
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.config.schema import ConfigError, device_tables, load_toml, parse_section, setting
from wavestack.drivers.pi_gcs import HEXAPOD_AXES, HexapodLimits, PIHexapod

__all__ = ["HexapodSettings", "build_hexapod", "hexapod_limits", "load_hexapod_config", "parse_hexapod_config"]

_AXIS = re.compile(r"[A-Za-z0-9_]{1,16}")


@dataclass(frozen=True)
class HexapodSettings:
    """``[hexapod]``: the PI GCS 2.0 controller the station drives and its move limits."""

    url: str = setting(url_kinds=("tcp", "socket", "sim", "device"),
                       doc="tcp://HOST[:PORT] (port 50000 by default), a serial port, socket:// or sim://")
    soft_lower: tuple[float, ...] = setting(doc="soft lower limit per axis (mm for X Y Z, deg for U V W)")
    soft_upper: tuple[float, ...] = setting(doc="soft upper limit per axis, same units")
    max_step: tuple[float, ...] = setting(minimum=0.0, doc="largest step per move from the position read back, "
                                                           "per axis, same units (> 0)")
    axes: tuple[str, ...] = setting(HEXAPOD_AXES, doc="driven axes in the controller's names, e.g. X Y Z U V W")
    timeout_s: float = setting(2.0, minimum=0.01, maximum=60.0, doc="timeout of each exchange, s")
    move_timeout_s: float = setting(30.0, minimum=0.01, maximum=3600.0, doc="longest wait on target, s")
    pivot_mm: tuple[float, float, float] | None = setting(None, doc="pivot point (x, y, z) set at start-up, mm")
    velocity: float | None = setting(None, minimum=0.0, maximum=1000.0,
                                     doc="platform velocity set at start-up (VLS), mm/s (> 0)")


def parse_hexapod_config(document: Mapping[str, Any], *, source: str, table: str = "hexapod") -> HexapodSettings:
    """Build the settings from a parsed TOML document holding table ``[table]``.

    Raises
    ------
    ConfigError
        Missing table, any key error :func:`wavestack.config.parse_section` reports, or inconsistent
        values (axis names, array lengths differing from ``axes``, lower >= upper, a zero step or
        velocity); each message names ``source`` and the key.
    """
    main, _simulator = device_tables(document, table, what="the PI GCS controller settings", source=source)
    settings = parse_section(HexapodSettings, main, source=source, section=table)
    where = f"{source}: [{table}]"
    bad = [axis for axis in settings.axes if not _AXIS.fullmatch(axis)]
    if not settings.axes or bad or len(set(settings.axes)) != len(settings.axes):
        raise ConfigError(f"{where} axes: expected distinct axis names of letters, digits or '_', "
                          f"got {list(settings.axes)}")
    for key in ("soft_lower", "soft_upper", "max_step"):
        if len(getattr(settings, key)) != len(settings.axes):
            raise ConfigError(f"{where} {key}: expected {len(settings.axes)} values, one per axis "
                              f"{list(settings.axes)}, got {len(getattr(settings, key))}")
    for axis, lower, upper in zip(settings.axes, settings.soft_lower, settings.soft_upper):
        if not lower < upper:
            raise ConfigError(f"{where} soft_lower: expected < soft_upper on axis {axis}, got {lower:g} >= {upper:g}")
    for axis, step in zip(settings.axes, settings.max_step):
        if not step > 0.0:
            raise ConfigError(f"{where} max_step: expected > 0 on axis {axis}, got {step:g}")
    if settings.velocity is not None and not settings.velocity > 0.0:
        raise ConfigError(f"{where} velocity: expected > 0 mm/s, got {settings.velocity:g}")
    return settings


def load_hexapod_config(path: str | Path, *, table: str = "hexapod") -> HexapodSettings:
    """Read ``[table]`` from a TOML file (see :func:`parse_hexapod_config`)."""
    return parse_hexapod_config(load_toml(path), source=str(path), table=table)


def hexapod_limits(settings: HexapodSettings) -> HexapodLimits:
    """The driver's move limits the settings describe."""
    return HexapodLimits(soft={axis: (lo, hi) for axis, lo, hi in zip(settings.axes, settings.soft_lower,
                                                                          settings.soft_upper)},
                         max_step=dict(zip(settings.axes, settings.max_step)))


def build_hexapod(settings: HexapodSettings) -> PIHexapod:
    """The driver the settings describe (not yet opened; pivot and velocity are set by the caller)."""
    return PIHexapod(settings.url, settings.axes, limits=hexapod_limits(settings), timeout_s=settings.timeout_s)
