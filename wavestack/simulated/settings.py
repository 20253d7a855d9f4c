"""The configuration's simulator tables turned into the simulators' own settings (pure, no simulator started).

The configuration declares what a station file may say about its simulated devices
(``[camera.simulator]``, ``[pzt.simulator]``, ``[plc.simulator]``, ``[hexapod.simulator]``,
``[optic]``, ``[bench]``, ``[lenslets]``) as settings of its own, and imports no simulator; the
simulators keep their own parameter types, written from the device's side. This module is the one
place that maps the first onto the second. A simulator's own checks run here: a value the schema
accepted but the simulator refuses (an annulus whose obscuration leaves the outer circle, limits of
the wrong length) is a :class:`~wavestack.config.ConfigError` naming the file and the table.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from wavestack.config import ConfigError, PlcConfig
from wavestack.config.camera import CameraSettings, CameraSimulatorSettings
from wavestack.config.hexapod_sim import HexapodSimulatorSettings
from wavestack.config.plc import MachineModelSettings, PlcSimulatorSettings
from wavestack.config.pzt import PiezoSimulatorSettings
from wavestack.simulators.mdt693b import MDT693BDevice, MDT693BPersonality
from wavestack.simulators.pi_gcs import HexapodSimSettings
from wavestack.simulators.plc import (MachineSimSettings, PlcSimLayout, PolishingMachine, PolishingStation, RemovalTarget,
                                      read_key_file)
from wavestack.simulators.gige import GigESimSettings
from wavestack.simulators.u3v import U3VSimSettings

__all__ = ["as_simulator", "camera_settings", "hexapod_settings", "machine_settings", "piezo_device", "plc_layout",
           "polishing_machine", "polishing_station"]

T = TypeVar("T")


def _nested_type(hint: Any) -> type | None:
    """The dataclass a field's hint names (also inside ``X | None``), or None."""
    if dataclasses.is_dataclass(hint):
        return hint
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        for arg in typing.get_args(hint):
            if dataclasses.is_dataclass(arg):
                return arg
    return None


def as_simulator(value: Any, kind: type[T], *, source: str, table: str) -> T:
    """``value`` (a configuration's settings) as the simulator's settings ``kind``, field by field.

    Both are frozen dataclasses with the same field names; a nested settings value (a sub-table)
    becomes the simulator's nested type. The simulator's own checks run.

    Raises
    ------
    ConfigError
        The simulator refuses a value; the message names ``source`` and ``[table]``.
    """
    hints = typing.get_type_hints(kind)
    values = {}
    for spec in dataclasses.fields(kind):  # type: ignore[arg-type]
        item = getattr(value, spec.name)
        nested = _nested_type(hints[spec.name])
        values[spec.name] = (as_simulator(item, nested, source=source, table=f"{table}.{spec.name}")
                             if nested is not None and item is not None else item)
    try:
        return kind(**values)
    except ValueError as error:
        raise ConfigError(f"{source}: [{table}] {error}") from None


def camera_settings(camera: CameraSettings, sim: CameraSimulatorSettings) -> U3VSimSettings | GigESimSettings:
    """The simulated camera's power-on state, on the transport ``[camera] url`` names (``sim://u3v``, ``sim://gige``)."""
    if camera.transport == "gige":
        return GigESimSettings(serial=sim.serial[:16], width=sim.width, height=sim.height,
                               pixel_format=sim.pixel_format, frame_rate_hz=sim.frame_rate_hz)
    return U3VSimSettings(serial=sim.serial, width=sim.width, height=sim.height, pixel_format=sim.pixel_format,
                          frame_rate_hz=sim.frame_rate_hz, zipped_xml=sim.zipped_xml)


def piezo_device(sim: PiezoSimulatorSettings) -> MDT693BDevice:
    """A fresh simulated MDT693B with the configured personality."""
    star = sim.prompt == "*"
    return MDT693BDevice(MDT693BPersonality(
        model=sim.model, echo=sim.echo, prompt=sim.prompt, firmware=sim.firmware, serial_number=sim.serial_number,
        vlimit_v=sim.vlimit_v, decimals=1 if star else 2, compatibility_mode=sim.compatibility_mode))


def hexapod_settings(sim: HexapodSimulatorSettings, *, source: str = "", table: str = "hexapod") -> HexapodSimSettings:
    """The simulated PI controller's settings (a rotating hexapod pivots about the origin unless told).

    Raises
    ------
    ConfigError
        Inconsistent values (limits, axes and positions of different lengths, a velocity above
        ``max_velocity``).
    """
    pivot = sim.pivot
    if pivot is None and any(axis in ("U", "V", "W") for axis in sim.axes):
        pivot = (0.0, 0.0, 0.0)
    try:
        return HexapodSimSettings(axes=sim.axes, low_limits=sim.low_limits, high_limits=sim.high_limits,
                                  velocity=sim.velocity, max_velocity=sim.max_velocity, pivot=pivot,
                                  initial_position=sim.initial_position, idn=sim.idn, referenced=sim.referenced,
                                  servo=sim.servo, reference_time_s=sim.reference_time_s)
    except ValueError as error:
        raise ConfigError(f"{source}: [{table}.simulator] {error}") from None


def plc_layout(plc: PlcConfig) -> PlcSimLayout:
    """The simulated PLC's register layout, from the same settings as the driver's map."""
    link = plc.link
    return PlcSimLayout(
        unit_id=link.unit_id, self_check_register=link.self_check_register, self_check_value=link.self_check_value,
        self_check_word_order=link.self_check_word_order or link.word_order,
        heartbeat_register=link.heartbeat_register, rearm_register=link.rearm_register,
        status_register=link.status_register, command_block=link.command_block, output_block=link.output_block,
        command_word_order=link.command_word_order or link.word_order,
        output_word_order=link.output_word_order or link.word_order, watchdog_timeout_s=link.watchdog_timeout_s,
        read_function=link.read_function_code, single_write_function=link.single_write_function_code,
        pass_duration_s=plc.simulator.polishing.pass_duration_s if plc.simulator else 0.0,
        job_register=link.job_register, machine_register=link.machine_register, job_word_order=link.word_order,
        owner_register=link.owner_register, display_register=link.display_register)


def machine_settings(plc: PlcConfig, job_folder: str | Path | None = None) -> MachineSimSettings:
    """The simulated machine's settings from ``[plc.simulator.machine]`` (defaults if absent).

    The job folder is ``job_folder`` if given, else the table's, else ``[plc] job_folder``.

    Raises
    ------
    ConfigError
        No job folder anywhere.
    """
    model = (plc.simulator.machine if plc.simulator else None) or MachineModelSettings()
    key_file = plc.job_key_path()
    try:
        job_key = None if key_file is None else read_key_file(key_file)
    except ValueError as error:
        raise ConfigError(f"{plc.source}: [plc] job_key_file: {error}") from None
    folder = job_folder or model.job_folder or plc.link.job_folder
    if folder is None:
        raise ConfigError(f"{plc.source}: the simulated machine needs a job folder: [plc.simulator.machine] "
                          "job_folder or [plc] job_folder")
    return MachineSimSettings(
        Path(folder), time_scale=model.time_scale, tif_fwhm_mm=model.tif_fwhm_mm,
        tif_peak_rate_nm_s=model.tif_peak_rate_nm_s, width_error=model.width_error, rate_error=model.rate_error,
        efficiency_spread=model.efficiency_spread, noise_nm=model.noise_nm, seed=model.seed,
        max_points=model.max_points, max_total_dwell_s=model.max_total_dwell_s,
        max_dwell_per_point_s=model.max_dwell_per_point_s, max_feed_mm_s=model.max_feed_mm_s,
        travel_x_mm=model.travel_x_mm, travel_y_mm=model.travel_y_mm, job_key=job_key)


def polishing_machine(plc: PlcConfig, target: RemovalTarget | None,
                      job_folder: str | Path | None = None) -> PolishingMachine:
    """A fresh simulated machine polishing ``target`` (None: progress only); see :func:`machine_settings`."""
    return PolishingMachine(machine_settings(plc, job_folder), target)


def polishing_station(plc: PlcConfig) -> PolishingStation:
    """The simulated PLC's display model from ``[plc.simulator.polishing]`` (defaults if absent)."""
    model = (plc.simulator or PlcSimulatorSettings()).polishing
    return PolishingStation(model.initial_surface_nm, efficiency=model.efficiency,
                            efficiency_spread=model.efficiency_spread, noise_nm=model.noise_nm,
                            max_removal_nm=model.max_removal_nm, seed=model.seed)
