"""PLC configuration: the shipped files load, bad files are refused naming file, key and expectation."""

from __future__ import annotations

from pathlib import Path

import pytest

from wavestack.config.plc import PlcLinkSettings, load_plc_config
from wavestack.config.schema import ConfigError
from wavestack.simulated import plc_layout, polishing_station

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"

MINIMAL = """
[plc]
url = "tcp://10.0.0.5:502"
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plc.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_simulator_file_equals_the_built_in_defaults() -> None:
    from_file = load_plc_config(CONFIG_DIR / "plc-sim.toml")
    built_in = load_plc_config(None)
    assert from_file.link == built_in.link and from_file.simulator == built_in.simulator
    assert from_file.link.n_terms == len(from_file.simulator.polishing.initial_surface_nm)  # type: ignore[union-attr]


def test_the_real_plc_example_loads_without_a_simulator() -> None:
    config = load_plc_config(CONFIG_DIR / "plc-example.toml")
    assert config.simulator is None
    assert (config.link.host, config.link.port) == ("192.168.10.20", 502)
    assert config.link.register_map().command.word_order == "ABCD"


def test_driver_map_and_simulator_layout_come_from_the_same_values(tmp_path: Path) -> None:
    config = load_plc_config(write(tmp_path, MINIMAL + 'word_order = "BADC"\ncommand_word_order = "DCBA"\n'
                                   "command_block = [100, 8]\noutput_block = [200, 8]\n"
                                   "[plc.simulator.polishing]\ninitial_surface_nm = [1.0, 2.0, 3.0]\n"))
    register_map, layout = config.link.register_map(), plc_layout(config)
    assert (layout.command_block, layout.output_block) == ((100, 8), (200, 8))
    assert (register_map.command.start, register_map.command.count) == layout.command_block
    assert (register_map.command.word_order, layout.command_word_order) == ("DCBA", "DCBA")
    assert (register_map.output.word_order, layout.output_word_order) == ("BADC", "BADC")
    assert (register_map.self_check.word_order, layout.self_check_word_order) == ("BADC", "BADC")
    assert polishing_station(config).n_terms == layout.n_terms == 3
    timing = config.link.link_timing()
    assert timing.io_timeout_s == PlcLinkSettings().io_timeout_s


def test_the_simulator_answers_the_function_codes_the_driver_is_configured_with(tmp_path: Path) -> None:
    # A PLC configured for input registers (FC4) and single writes by FC16 must be simulated so: the
    # simulator refuses every function code its map does not list (exception 1).
    config = load_plc_config(write(tmp_path, MINIMAL + "read_function_code = 4\nsingle_write_function_code = 16\n"))
    register_map, layout = config.link.register_map(), plc_layout(config)
    assert layout.read_function == register_map.status.read_function == 4
    assert layout.single_write_function == register_map.heartbeat.write_function == 16


@pytest.mark.parametrize(("text", "message"), [
    ("[pzt]\nurl = 'x'\n", r"plc.toml: missing table \[plc\]"),
    (MINIMAL + "unit = 2\n", r"\[plc\] unknown key 'unit'"),
    (MINIMAL + 'word_order = "ABDC"\n', r"\[plc\] word_order: expected one of 'ABCD', 'CDAB', 'BADC', 'DCBA'"),
    (MINIMAL + "unit_id = 300\n", r"unit_id: expected <= 255"),
    (MINIMAL + "command_block = [100]\n", r"command_block: expected an array of 2 values"),
    (MINIMAL + "heartbeat_register = 20\n", r"\[plc\] register map: .*overlaps"),
    (MINIMAL + "command_block = [100, 33]\n", r"register map: command block must be 2 \+ 2 n"),
    (MINIMAL + "read_function_code = 6\n", r"read_function_code: expected one of 3, 4"),
    (MINIMAL + "single_write_function_code = 5\n", r"single_write_function_code: expected one of 6, 16"),
    (MINIMAL + "reconnect_initial_s = 5.0\nreconnect_max_s = 1.0\n", r"must not exceed reconnect_max_s"),
    ('[plc]\nurl = "socket://10.0.0.5:502"\n', r"URL 'socket://10.0.0.5:502' is not allowed; expected tcp://"),
    ('[plc]\nurl = "tcp://10.0.0.5"\n', r"url: expected tcp://HOST:PORT"),
    ('[plc]\nurl = "tcp://10.0.0.5:70000"\n', r"port must be 1..65535"),
    (MINIMAL + "[plc.simulator.polishing]\ninitial_surface_nm = [1.0, 2.0]\n",
     r"\[plc.simulator.polishing\] initial_surface_nm: expected 15 terms .*got 2"),
    (MINIMAL + "[plc.simulator.polishing]\nefficiency = 1.5\n", r"\[plc.simulator.polishing\] efficiency"),
    (MINIMAL + "[plc.simulator]\nspeed = 1\n", r"\[plc.simulator\] unknown key 'speed'"),
])
def test_bad_files_are_refused_naming_file_key_and_expectation(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=message) as caught:
        load_plc_config(path)
    assert str(path) in str(caught.value)


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_plc_config(tmp_path / "absent.toml")


def test_ipv6_urls_are_split() -> None:
    settings = PlcLinkSettings(url="tcp://[::1]:1502")
    assert (settings.host, settings.port) == ("::1", 1502)
