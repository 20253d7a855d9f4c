"""Piezo configuration: the shipped files load, bad files fail naming the file and the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from wavestack.cli.sim_pzt import default_pzt_config
from wavestack.config.pzt import (
    PiezoSettings,
    PiezoSimulatorSettings,
    build_calibration,
    build_piezo,
    load_pzt_config,
    parse_pzt_config,
)
from wavestack.config.schema import ConfigError
from wavestack.simulated import piezo_device

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"
MINIMAL = 'url = "sim://mdt693b"\nvolts_per_radian = 2.0\nbias_v = 75.0\n'


def write(tmp_path: Path, pzt_body: str, extra: str = "") -> Path:
    path = tmp_path / "station.toml"
    path.write_text(f"[pzt]\n{pzt_body}\n{extra}", encoding="utf-8")
    return path


def test_shipped_simulator_config_equals_the_built_in_defaults() -> None:
    from_file = load_pzt_config(CONFIG_DIR / "pzt-sim.toml")
    built_in = parse_pzt_config(default_pzt_config(), source="built-in")
    assert from_file == built_in
    settings, simulator = from_file
    assert settings.url == "sim://mdt693b"
    assert simulator == PiezoSimulatorSettings()


def test_example_hardware_config_loads() -> None:
    settings, _ = load_pzt_config(CONFIG_DIR / "pzt-mdt693b.example.toml")
    assert settings.url == "/dev/ttyUSB0"
    assert settings.software_max_v == 100.0


def test_minimal_config_takes_defaults_and_builds_objects(tmp_path: Path) -> None:
    settings, simulator = load_pzt_config(write(tmp_path, MINIMAL, '[pzt.simulator]\nprompt = "*"\nvlimit_v = 75\n'))
    assert settings == PiezoSettings(url="sim://mdt693b", volts_per_radian=2.0, bias_v=75.0)
    assert (simulator.prompt, simulator.vlimit_v) == ("*", 75.0)
    piezo = build_piezo(settings)
    assert (piezo.url, piezo.axes, piezo.readback_tolerance_v) == ("sim://mdt693b", ("x",), 0.5)
    assert build_calibration(settings).voltage_for(1.0) == 77.0
    device = piezo_device(simulator)
    assert (device.personality.prompt, device.vlimit_v, device.personality.decimals) == ("*", 75.0, 1)



def test_an_mdt693a_or_a_b_unit_in_its_a_mode_is_configured_end_to_end(tmp_path: Path) -> None:
    settings, simulator = load_pzt_config(write(
        tmp_path, MINIMAL + 'command_set = "mdt693a"\n', "[pzt.simulator]\ncompatibility_mode = true\n"))
    assert build_piezo(settings).configured_command_set == "mdt693a"
    assert piezo_device(simulator).compatibility_mode is True
    _, a_unit = load_pzt_config(write(tmp_path, MINIMAL, '[pzt.simulator]\nmodel = "MDT693A"\n'))
    assert piezo_device(a_unit).personality.model == "MDT693A"
    # the default detects the command set at open
    assert build_piezo(load_pzt_config(write(tmp_path, MINIMAL))[0]).configured_command_set == "auto"

@pytest.mark.parametrize(
    ("body", "extra", "key", "expectation"),
    [
        (MINIMAL + "vlimt = 100\n", "", "vlimt", "unknown key"),
        (MINIMAL + 'timeout_s = "fast"\n', "", "timeout_s", "expected a number"),
        (MINIMAL + "software_max_v = 200\n", "", "software_max_v", "expected <= 150"),
        (MINIMAL + "settle_s = -1\n", "", "settle_s", "expected >= 0"),
        (MINIMAL.replace("sim://mdt693b", "tcp://10.0.0.5:502"), "", "url", "is not allowed"),
        (MINIMAL.replace("sim://mdt693b", "ttyUSB0"), "", "url", "is not allowed"),
        (MINIMAL + 'axes = ["x", "w"]\n', "", "axes", "expected one of"),
        (MINIMAL + 'axes = ["x", "x"]\n', "", "axes", "distinct"),
        (MINIMAL + 'phase_axis = "y"\n', "", "phase_axis", "one of axes"),
        (MINIMAL + "software_min_v = 80\nsoftware_max_v = 70\n", "", "software_min_v", "expected <"),
        (MINIMAL.replace("2.0", "0"), "", "volts_per_radian", "nonzero"),
        ('url = "sim://mdt693b"\nbias_v = 75.0\n', "", "volts_per_radian", "missing required key"),
        (MINIMAL, "[pzt.simulator]\nvlimit_v = 120\n", "vlimit_v", "expected one of"),
        (MINIMAL, '[pzt.simulator]\nprompt = "#"\n', "prompt", "expected one of"),
        (MINIMAL, "[pzt.simulator]\nechoo = false\n", "echoo", "unknown key"),
    ],
)
def test_bad_config_names_file_and_key(tmp_path: Path, body: str, extra: str, key: str, expectation: str) -> None:
    path = write(tmp_path, body, extra)
    with pytest.raises(ConfigError) as caught:
        load_pzt_config(path)
    message = str(caught.value)
    assert str(path) in message
    assert key in message
    assert expectation in message


def test_missing_table_and_missing_file(tmp_path: Path) -> None:
    other = tmp_path / "other.toml"
    other.write_text("[camera]\nurl = 'usb://1'\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"other\.toml: missing table \[pzt\]"):
        load_pzt_config(other)
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_pzt_config(tmp_path / "absent.toml")


def test_other_instruments_tables_are_left_alone(tmp_path: Path) -> None:
    path = write(tmp_path, MINIMAL, "[plc]\nhost = '127.0.0.1'\n")
    assert load_pzt_config(path)[0].bias_v == 75.0
