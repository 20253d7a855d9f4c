"""Configuration of the simulated PI GCS controller: table ``[hexapod.simulator]``.

``[hexapod]`` itself belongs to the driver's settings (:mod:`wavestack.config.hexapod`); this module
reads only its ``simulator`` sub-table, so one station file can describe both ends. The same schema
under another device table (``[field_stage.simulator]``, with axes ``["X", "Y"]``) describes the
bench's field stage: pass ``table="field_stage"``. Every key is optional; the defaults are the
six-axis hexapod of :class:`~wavestack.simulators.pi_gcs.HexapodSimSettings`.

Example::

    [hexapod.simulator]
    axes = ["X", "Y", "Z", "U", "V", "W"]
    low_limits = [-17.0, -16.0, -6.5, -14.5, -14.5, -20.0]
    high_limits = [17.0, 16.0, 6.5, 14.5, 14.5, 20.0]
    velocity = 2.0
    pivot = [0.0, 0.0, 50.0]
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.config.schema import ConfigError, device_tables, load_toml, parse_section, setting
from wavestack.simulators.pi_gcs import HEXAPOD_AXES, HexapodSimSettings

__all__ = ["HexapodSimulatorSettings", "load_hexapod_sim_config", "parse_hexapod_sim_config"]

_DEFAULTS = HexapodSimSettings()
_ROTATION_AXES = ("U", "V", "W")


@dataclass(frozen=True)
class HexapodSimulatorSettings:
    """``[hexapod.simulator]``: the simulated controller's axes, travel, velocity, pivot and identity."""

    axes: tuple[str, ...] = setting(HEXAPOD_AXES, doc="axis identifiers in controller order")
    low_limits: tuple[float, ...] = setting(_DEFAULTS.low_limits, doc="TMN? per axis, mm or deg")
    high_limits: tuple[float, ...] = setting(_DEFAULTS.high_limits, doc="TMX? per axis, mm or deg")
    velocity: float = setting(_DEFAULTS.velocity, minimum=1e-9, maximum=1e6, doc="power-on VLS, units/s")
    max_velocity: float = setting(_DEFAULTS.max_velocity, minimum=1e-9, maximum=1e6, doc="largest VLS accepted")
    pivot: tuple[float, float, float] | None = setting(
        None, doc="pivot R S T, mm; default [0, 0, 0] with rotation axes U V W, none without them")
    initial_position: tuple[float, ...] | None = setting(None, doc="power-on positions (default: 0 clipped to limits)")
    idn: str = setting(_DEFAULTS.idn, doc="the *IDN? answer")
    referenced: bool = setting(True, doc="axes referenced at power-on (else FRF first)")
    servo: bool = setting(True, doc="servo on at power-on")
    reference_time_s: float = setting(_DEFAULTS.reference_time_s, minimum=0.0, maximum=600.0,
                                      doc="shortest reference move (FRF), s")

    def simulator_settings(self) -> HexapodSimSettings:
        """The simulator's own settings (raises ValueError for inconsistent values)."""
        pivot = self.pivot
        if pivot is None and any(axis in _ROTATION_AXES for axis in self.axes):
            pivot = (0.0, 0.0, 0.0)
        return HexapodSimSettings(axes=self.axes, low_limits=self.low_limits, high_limits=self.high_limits,
                                  velocity=self.velocity, max_velocity=self.max_velocity, pivot=pivot,
                                  initial_position=self.initial_position, idn=self.idn,
                                  referenced=self.referenced, servo=self.servo,
                                  reference_time_s=self.reference_time_s)


def parse_hexapod_sim_config(document: Mapping[str, Any], *, source: str, table: str = "hexapod") -> HexapodSimSettings:
    """The simulator settings of ``[<table>.simulator]`` in a parsed TOML document.

    Raises
    ------
    ConfigError
        Missing ``[<table>]``, any key error :func:`wavestack.config.parse_section` reports, or
        inconsistent values (limits, axes and positions of different lengths, empty ranges, a
        velocity above ``max_velocity``); each message names ``source`` and the table.

    Examples
    --------
    >>> doc = {"field_stage": {"simulator": {"axes": ["X", "Y"], "low_limits": [-40, -40],
    ...                                      "high_limits": [40, 40]}}}
    >>> settings = parse_hexapod_sim_config(doc, source="bench.toml", table="field_stage")
    >>> settings.axes, settings.pivot
    (('X', 'Y'), None)
    """
    _, simulator_table = device_tables(document, table, what="the controller settings", source=source)
    section = f"{table}.simulator"
    schema = parse_section(HexapodSimulatorSettings, simulator_table or {}, source=source, section=section)
    try:
        return schema.simulator_settings()
    except ValueError as error:
        raise ConfigError(f"{source}: [{section}] {error}") from None


def load_hexapod_sim_config(path: str | Path | None, *, table: str = "hexapod") -> HexapodSimSettings:
    """Read ``[<table>.simulator]`` from a TOML file; None gives the built-in hexapod."""
    if path is None:
        return HexapodSimSettings()
    return parse_hexapod_sim_config(load_toml(path), source=str(path), table=table)
