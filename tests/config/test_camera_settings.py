"""The [camera] tables: URLs, ranges and the simulator's power-on state."""

from __future__ import annotations

import pytest

from wavestack.config.camera import CameraSettings, CameraSimulatorSettings, parse_camera_config
from wavestack.config.schema import ConfigError


def test_defaults_describe_the_simulated_camera() -> None:
    camera, simulator = parse_camera_config({"camera": {}}, source="station.toml")
    assert camera == CameraSettings() and camera.simulated and camera.serial is None
    assert simulator == CameraSimulatorSettings()


@pytest.mark.parametrize(("url", "serial"), [("usb://", None), ("usb://AB1234", "AB1234")])
def test_usb_urls_pick_the_first_camera_or_one_by_serial(url: str, serial: str | None) -> None:
    camera, _ = parse_camera_config({"camera": {"url": url}}, source="station.toml")
    assert camera.serial == serial and not camera.simulated


@pytest.mark.parametrize(("table", "expected"), [
    ({}, r"station.toml: missing table \[camera\]"),
    ({"camera": {"url": "/dev/video0"}}, r"\[camera\] url: URL '/dev/video0' is not allowed; expected usb://"),
    ({"camera": {"url": "sim://mdt693b"}}, r"\[camera\] url: expected sim://u3v"),
    ({"camera": {"pixel_format": "Mono10"}}, r"\[camera\] pixel_format: expected one of"),
    ({"camera": {"exposure_us": 0}}, r"\[camera\] exposure_us: expected >= 1"),
    ({"camera": {"simulator": {"width": 4}}}, r"\[camera.simulator\] width: expected >= 16"),
    ({"camera": {"simulator": {"fps": 4}}}, r"\[camera.simulator\] unknown key 'fps'"),
])
def test_bad_tables_name_file_key_and_expectation(table: dict, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected):
        parse_camera_config(table, source="station.toml")
