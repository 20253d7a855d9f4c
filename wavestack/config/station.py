"""A station's configuration: one TOML file, one table per device and per stage, all checked on load.

Tables (see ``wavestack/config/default.toml``, the simulated station ``wavestack run`` uses by default):

``[station]``
    :class:`StationSettings`: the kind of station (``interferometer`` or ``shack-hartmann``),
    timeouts, result age limit, wavelength.
``[processing]``
    :class:`~wavestack.config.processing.ProcessingSettings`: phase method, fit (interferometer).
``[shack_hartmann]``
    :class:`~wavestack.config.shack_hartmann.ShackHartmannSettings`: lenslet geometry, pupil,
    modes (Shack-Hartmann station, which has no ``[processing]``, ``[pzt]`` or ``[bench]``).
``[camera]``, ``[camera.simulator]``
    :mod:`wavestack.config.camera`; ``url = "sim://u3v"`` makes the station build the simulated
    bench (and then needs ``[optic]`` and, for phase shifting, ``[bench]``).
``[pzt]``, ``[pzt.simulator]``
    :mod:`wavestack.config.pzt`; required for the ``psi`` method.
``[plc]``, ``[plc.simulator]``
    :mod:`wavestack.config.plc`; optional. ``url = "sim://plc"`` runs the simulated PLC.
``[outputs]``
    :class:`OutputSettings`: what goes to the PLC, through the safety stage.
``[optic]`` (with ``[optic.aperture]`` and optionally ``[optic.surface]``), ``[bench]``
    The simulated test optic and how the simulated piezo moves its fringes. ``[optic.surface]``
    (:class:`~wavestack.config.simulated_bench.SurfaceSimulatorSettings`) gives the optic a height map polishing can
    change; its ``map_file`` is read relative to the station file's folder, its ``wavelength_nm``
    defaults to ``[station] wavelength_nm`` and must equal it when given. These tables are
    settings only (:mod:`wavestack.config.simulated_bench`): the simulator starter
    (``wavestack.simulated``) builds the bench from them.
``[lenslets]``
    The simulated lenslet array (:class:`~wavestack.config.simulated_bench.LensletSimulatorSettings`) of a
    simulated Shack-Hartmann camera. ``pitch_px``, ``offset_px``, ``grid_shape``,
    ``orientation_deg`` and ``lattice`` default to the ``[shack_hartmann]`` values (``lattice``
    must be given when the sensor's is ``"auto"``), ``gain_px`` to ``f lambda / p**2`` from them
    and the wavelength, ``bit_depth`` to the simulated camera's pixel format.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from wavestack.config._checks import BIT_DEPTH
from wavestack.config.camera import CameraSimulatorSettings, parse_camera_config
from wavestack.config.schema import ConfigError, parse_section, parse_toml, read_config_text
from wavestack.config.surface import SurfaceSettings
from wavestack.config.plc import parse_plc_config
from wavestack.config.pzt import parse_pzt_config
from wavestack.config.processing import ProcessingSettings
from wavestack.config.shack_hartmann import ShackHartmannSettings
from wavestack.config.simulated_bench import BenchSimulatorSettings, LensletSimulatorSettings, OpticSimulatorSettings
from wavestack.config.station_rules import check_station_rules
from wavestack.config.station_schema import OutputSettings, StationConfig, StationSettings
from wavestack.pipeline.calibration import CalibrationRefused, read_calibration

_TABLES = ("station", "processing", "camera", "pzt", "plc", "outputs", "optic", "bench", "shack_hartmann",
           "lenslets", "surface")
_SHACK_HARTMANN_ONLY = ("shack_hartmann", "lenslets")
_INTERFEROMETER_ONLY = ("processing", "pzt", "bench", "surface")
#: The simulated station, shipped inside the package (the one default station file).
DEFAULT_CONFIG = Path(__file__).resolve().parent / "default.toml"


def _section(schema: type, document: Mapping[str, Any], name: str, source: str) -> Any:
    return parse_section(schema, document.get(name, {}), source=source, section=name)


def parse_station_config(text: str, *, source: str) -> StationConfig:
    """Check a station configuration given as TOML text.

    Raises
    ------
    ConfigError
        Malformed TOML, an unknown top-level table, or any key error of any table; also a
        ``psi`` station without ``[pzt]``, or a simulated camera without ``[optic]``; a
        Shack-Hartmann station without ``[shack_hartmann]`` (or, simulated, ``[lenslets]``) or
        with an interferometer's table, and the reverse; phase steps the algorithm cannot use
        (:meth:`ProcessingSettings.check`) and the rules across tables of
        :mod:`wavestack.config.station_rules`.
    """
    document = parse_toml(text, source)
    unknown = sorted(set(document) - set(_TABLES))
    if unknown:
        raise ConfigError(f"{source}: unknown table [{unknown[0]}]; expected tables: {', '.join(_TABLES)}")
    station = _section(StationSettings, document, "station", source)
    if station.kind == "shack-hartmann":
        return _parse_shack_hartmann(document, station, text=text, source=source)
    misplaced = [name for name in _SHACK_HARTMANN_ONLY if name in document]
    if misplaced:
        raise ConfigError(f"{source}: [{misplaced[0]}] belongs to a Shack-Hartmann station; "
                          "expected [station] kind = 'shack-hartmann' with it")
    processing = _section(ProcessingSettings, document, "processing", source)
    processing.check(source=source)
    camera, camera_simulator = parse_camera_config(document, source=source)
    pzt = pzt_simulator = None
    if "pzt" in document:
        pzt, pzt_simulator = parse_pzt_config(document, source=source)
    elif processing.method == "psi":
        raise ConfigError(f"{source}: [processing] method = 'psi' needs a [pzt] table (the phase shifter)")
    plc = parse_plc_config(document, source=source) if "plc" in document else None
    optic = None
    if camera.simulated:
        if "optic" not in document:
            raise ConfigError(f"{source}: [camera] url = 'sim://u3v' needs an [optic] table (the simulated optic)")
        optic = _simulated_surface(_section(OpticSimulatorSettings, document, "optic", source), document["optic"], station,
                                   source)
    config = StationConfig(
        source=source, text=text, station=station,
        processing=processing, camera=camera, camera_simulator=camera_simulator,
        pzt=pzt, pzt_simulator=pzt_simulator, plc=plc,
        outputs=_section(OutputSettings, document, "outputs", source),
        optic=optic, bench=_section(BenchSimulatorSettings, document, "bench", source),
        surface=_section(SurfaceSettings, document, "surface", source),
    )
    config.surface.request(source)  # a tolerance that cannot be read is refused with the file
    check_station_rules(config)
    if config.processing.calibration is not None:
        path = Path(config.processing.calibration)
        config = with_calibration(config, path if path.is_absolute() else Path(source).parent / path)
    return config


def _parse_shack_hartmann(document: Mapping[str, Any], station: StationSettings, *, text: str,
                          source: str) -> StationConfig:
    """The tables of a ``kind = "shack-hartmann"`` station.

    Its ``processing`` is derived, not read: one frame per set, the ``[shack_hartmann]`` modes and
    ordering, nothing removed -- the view of the processing that the result records, recordings
    and live view share with an interferometer station.
    """
    misplaced = [name for name in _INTERFEROMETER_ONLY if name in document]
    if misplaced:
        raise ConfigError(f"{source}: [{misplaced[0]}] belongs to an interferometer station; a [station] "
                          "kind = 'shack-hartmann' station is configured by [shack_hartmann]")
    if "shack_hartmann" not in document:
        raise ConfigError(f"{source}: [station] kind = 'shack-hartmann' needs a [shack_hartmann] table "
                          "(lenslet pitch, focal length, pixel size, pupil)")
    sensor = _section(ShackHartmannSettings, document, "shack_hartmann", source)
    camera, camera_simulator = parse_camera_config(document, source=source)
    optic = lenslets = None
    if camera.simulated:
        missing = [name for name in ("optic", "lenslets") if name not in document]
        if missing:
            raise ConfigError(f"{source}: a simulated Shack-Hartmann camera (url = 'sim://u3v') needs "
                              f"[{missing[0]}] (the simulated optic and lenslet array)")
        optic = _simulated_surface(_section(OpticSimulatorSettings, document, "optic", source), document["optic"], station,
                                   source)
        lenslets = _simulated_lenslets(document["lenslets"], sensor, station, camera_simulator, source)
    config = StationConfig(
        source=source, text=text, station=station,
        processing=ProcessingSettings(method="carrier", modes=sensor.modes, ordering=sensor.ordering, remove="none"),
        camera=camera, camera_simulator=camera_simulator, pzt=None, pzt_simulator=None,
        plc=parse_plc_config(document, source=source) if "plc" in document else None,
        outputs=_section(OutputSettings, document, "outputs", source),
        optic=optic, bench=BenchSimulatorSettings(), shack_hartmann=sensor, lenslets=lenslets,
    )
    check_station_rules(config)
    return config


def _simulated_surface(optic: OpticSimulatorSettings, table: Mapping[str, Any], station: StationSettings,
                       source: str) -> OpticSimulatorSettings:
    """``optic`` with ``[optic.surface]``, ``[optic.reference]``, ``[optic.ball]`` completed: map files found, the
    station's wavelength."""
    changes = {name: _completed(getattr(optic, name), table, name, station, source)
               for name in ("surface", "reference", "ball") if getattr(optic, name) is not None}
    return dataclasses.replace(optic, **changes)


def _completed(sub: Any, table: Mapping[str, Any], name: str, station: StationSettings, source: str) -> Any:
    """A sub-table of ``[optic]`` (surface, reference, ball) with its map file found and the station's wavelength."""
    given = table[name]  # parse_section has checked it is a table
    changes: dict[str, Any] = {}
    if "wavelength_nm" not in given:
        changes["wavelength_nm"] = station.wavelength_nm
    elif sub.wavelength_nm != station.wavelength_nm:
        raise ConfigError(f"{source}: [optic.{name}] wavelength_nm = {sub.wavelength_nm:g} does not match "
                          f"[station] wavelength_nm = {station.wavelength_nm:g}; expected the same or no key")
    if getattr(sub, "map_file", None) is not None:
        path = Path(sub.map_file)
        if not path.is_absolute():
            path = Path(source).parent / path
        if not path.is_file():
            raise ConfigError(f"{source}: [optic.{name}] map_file = {sub.map_file!r}: no such file ({path})")
        changes["map_file"] = str(path)
    return dataclasses.replace(sub, **changes)


def _simulated_lenslets(table: Any, sensor: ShackHartmannSettings, station: StationSettings,
                        camera: CameraSimulatorSettings, source: str) -> LensletSimulatorSettings:
    """``[lenslets]``, its absent geometry taken from ``[shack_hartmann]`` (module notes)."""
    depth = BIT_DEPTH[camera.pixel_format]
    try:
        parsed = parse_section(LensletSimulatorSettings, table, source=source, section="lenslets")
        given = set(table)
        derived: dict[str, Any] = {name: getattr(sensor, name) for name in ("pitch_px", "offset_px", "grid_shape",
                                                                           "orientation_deg") if name not in given}
        if "lattice" not in given:
            if sensor.lattice == "auto":
                raise ConfigError(f"{source}: [lenslets] lattice: the simulated array's kind ('square' or "
                                  f"'hexagonal') is needed when [shack_hartmann] lattice = 'auto'")
            derived["lattice"] = sensor.lattice
        if "gain_px" not in given:
            derived["gain_px"] = sensor.gain_px(station.wavelength_nm)
        if "bit_depth" not in given:
            derived["bit_depth"] = depth
        lenslets = dataclasses.replace(parsed, **derived)
    except ConfigError:
        raise
    except ValueError as error:  # the simulator's own checks
        raise ConfigError(f"{source}: [lenslets] {error}") from None
    if lenslets.bit_depth != depth:
        raise ConfigError(f"{source}: [lenslets] bit_depth {lenslets.bit_depth} does not match "
                          f"[camera.simulator] pixel_format {camera.pixel_format!r} ({depth} bits)")
    return lenslets


def load_station_config(path: str | Path | None = None) -> StationConfig:
    """Read and check a station file (None: the packaged ``default.toml``, the simulated station)."""
    path = DEFAULT_CONFIG if path is None else Path(path)
    return parse_station_config(read_config_text(path), source=str(path))


def with_calibration(config: StationConfig, path: str | Path) -> StationConfig:
    """The station with the reference calibration of ``path`` read, checked and in force.

    The file must be whole (its content hash), of the station's wavelength and, for a simulated
    camera, of its grid (a real camera's grid is checked on every set: a set of another grid or
    aperture is an invalid result naming why).

    Raises
    ------
    ConfigError
        One line naming the station file, the calibration and the reason.
    """
    if config.station.kind != "interferometer":
        raise ConfigError(f"{config.source}: [processing] calibration: a reference calibration applies to an "
                          "interferometer station")
    try:
        calibration = read_calibration(path)
        calibration.check_measurement(calibration.grid, config.station.wavelength_nm)
        if config.camera.simulated:
            sim = config.camera_simulator
            calibration.check_measurement((sim.height, sim.width))
    except CalibrationRefused as error:
        raise ConfigError(f"{config.source}: [processing] calibration: {error}") from None
    processing = dataclasses.replace(config.processing, calibration=str(path))
    return dataclasses.replace(config, processing=processing, calibration=calibration)
