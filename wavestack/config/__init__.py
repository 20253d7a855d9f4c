"""Configuration: TOML tables checked against frozen dataclass schemas, and the default station file.

One face for every settings schema: the schema machinery (:mod:`~wavestack.config.schema`), the
device tables (camera, piezo, PLC), the processing tables (interferometer, Shack-Hartmann) and
the station file that holds them all (:mod:`~wavestack.config.station`). ``default.toml`` beside
this module is the simulated station ``wavestack run`` uses without ``--config``.
"""

from __future__ import annotations

from wavestack.config._checks import BIT_DEPTH
from wavestack.drivers.device_path import DEVICE_PATH_RULE, check_device_path
from wavestack.config.camera import CameraSettings, CameraSimulatorSettings, parse_camera_config
from wavestack.config.plc import (
    MachineModelSettings,
    PlcConfig,
    PlcLinkSettings,
    PlcSimulatorSettings,
    PolishingModelSettings,
    load_plc_config,
    parse_plc_config,
)
from wavestack.config.processing import FitSettings, ProcessingSettings
from wavestack.config.pzt import (
    PiezoSettings,
    PiezoSimulatorSettings,
    build_calibration,
    build_piezo,
    load_pzt_config,
    parse_pzt_config,
)
from wavestack.config.schema import (
    URL_KINDS,
    ConfigError,
    device_tables,
    load_toml,
    parse_section,
    setting,
    url_kind,
)
from wavestack.config.shack_hartmann import ShackHartmannSettings
from wavestack.config.station import (
    DEFAULT_CONFIG,
    OutputSettings,
    StationConfig,
    StationSettings,
    load_station_config,
    parse_station_config,
)

__all__ = [
    "BIT_DEPTH", "CameraSettings", "DEVICE_PATH_RULE", "check_device_path", "CameraSimulatorSettings", "ConfigError", "DEFAULT_CONFIG", "FitSettings",
    "MachineModelSettings", "OutputSettings", "PiezoSettings", "PiezoSimulatorSettings", "PlcConfig", "PlcLinkSettings",
    "PlcSimulatorSettings", "PolishingModelSettings", "ProcessingSettings", "ShackHartmannSettings",
    "StationConfig", "StationSettings", "URL_KINDS", "build_calibration", "build_piezo", "build_simulated_device",
    "device_tables", "load_plc_config", "load_pzt_config", "load_station_config", "load_toml",
    "parse_camera_config", "parse_plc_config", "parse_pzt_config", "parse_section", "parse_station_config",
    "setting", "url_kind",
]
