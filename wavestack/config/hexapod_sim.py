"""Configuration of the simulated PI GCS controller: table ``[hexapod.simulator]``.

``[hexapod]`` itself belongs to the driver's settings (:mod:`wavestack.config.hexapod`); this module
reads only its ``simulator`` sub-table, so one station file can describe both ends. The same schema
under another device table (``[field_stage.simulator]``, with axes ``["X", "Y"]``) describes the
bench's field stage: pass ``table="field_stage"``. Every key is optional; the defaults are the
simulator's six-axis hexapod. Settings only: the simulator starter (``wavestack.simulated``) turns
them into the simulator's own settings, where its checks across keys run.

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

from wavestack.config.schema import device_tables, load_toml, parse_section, setting
from wavestack.drivers.pi_gcs import HEXAPOD_AXES

__all__ = ["HexapodSimulatorSettings", "load_hexapod_sim_config", "parse_hexapod_sim_config"]

#: The simulated controller's identity (its ``*IDN?`` answer).
IDN_DEFAULT = "Physik Instrumente (PI) GmbH & Co. KG, C-887.52, SIM0000001, wavestack simulator 1.0"


@dataclass(frozen=True)
class HexapodSimulatorSettings:
    """``[hexapod.simulator]``: the simulated controller's axes, travel, velocity, pivot and identity."""

    axes: tuple[str, ...] = setting(HEXAPOD_AXES, doc="axis identifiers in controller order")
    low_limits: tuple[float, ...] = setting((-17.0, -16.0, -6.5, -14.5, -14.5, -20.0), doc="TMN? per axis, mm or deg")
    high_limits: tuple[float, ...] = setting((17.0, 16.0, 6.5, 14.5, 14.5, 20.0), doc="TMX? per axis, mm or deg")
    velocity: float = setting(2.0, minimum=1e-9, maximum=1e6, doc="power-on VLS, units/s")
    max_velocity: float = setting(20.0, minimum=1e-9, maximum=1e6, doc="largest VLS accepted")
    pivot: tuple[float, float, float] | None = setting(
        None, doc="pivot R S T, mm; default [0, 0, 0] with rotation axes U V W, none without them")
    initial_position: tuple[float, ...] | None = setting(None, doc="power-on positions (default: 0 clipped to limits)")
    idn: str = setting(IDN_DEFAULT, doc="the *IDN? answer")
    referenced: bool = setting(True, doc="axes referenced at power-on (else FRF first)")
    servo: bool = setting(True, doc="servo on at power-on")
    reference_time_s: float = setting(0.2, minimum=0.0, maximum=600.0, doc="shortest reference move (FRF), s")


def parse_hexapod_sim_config(document: Mapping[str, Any], *, source: str,
                             table: str = "hexapod") -> HexapodSimulatorSettings:
    """The settings of ``[<table>.simulator]`` in a parsed TOML document.

    Raises
    ------
    ConfigError
        Missing ``[<table>]``, or any key error :func:`wavestack.config.parse_section` reports;
        each message names ``source`` and the table. Values inconsistent across keys (limits and
        axes of different lengths) are refused by the simulator starter.

    Examples
    --------
    >>> doc = {"field_stage": {"simulator": {"axes": ["X", "Y"], "low_limits": [-40, -40],
    ...                                      "high_limits": [40, 40]}}}
    >>> settings = parse_hexapod_sim_config(doc, source="bench.toml", table="field_stage")
    >>> settings.axes, settings.pivot
    (('X', 'Y'), None)
    """
    _, simulator_table = device_tables(document, table, what="the controller settings", source=source)
    return parse_section(HexapodSimulatorSettings, simulator_table or {}, source=source, section=f"{table}.simulator")


def load_hexapod_sim_config(path: str | Path | None, *, table: str = "hexapod") -> HexapodSimulatorSettings:
    """Read ``[<table>.simulator]`` from a TOML file; None gives the built-in hexapod."""
    if path is None:
        return HexapodSimulatorSettings()
    return parse_hexapod_sim_config(load_toml(path), source=str(path), table=table)
