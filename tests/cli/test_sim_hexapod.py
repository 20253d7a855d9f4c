"""The standalone hexapod simulator (``wavestack sim hexapod``) and its ``[hexapod.simulator]`` settings."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from sim_serving import serve_in_thread
from wavestack.cli.sim_hexapod import run_hexapod_simulator
from wavestack.config.hexapod_sim import load_hexapod_sim_config, parse_hexapod_sim_config
from wavestack.config.schema import ConfigError
from wavestack.simulated import hexapod_settings
from wavestack.simulators.pi_gcs import HexapodSimSettings

# What a config/hexapod-sim.toml would hold (the built-in hexapod, every key written out). It lives here
# until the merge ships it in config/ (tests/config/test_meaningful_config.py lists the shipped files).
EXAMPLE_TOML = (Path(__file__).resolve().parents[2] / "config" / "hexapod-sim.toml").read_text(encoding="utf-8")


@pytest.fixture
def example_file(tmp_path: Path) -> Path:
    path = tmp_path / "hexapod-sim.toml"
    path.write_text(EXAMPLE_TOML, encoding="utf-8")
    return path


def _ask(port: int, command: bytes) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=5.0) as link:
        link.sendall(command)
        answer = b""
        while not answer.endswith(b"\n") or answer.endswith(b" \n"):
            chunk = link.recv(4096)
            assert chunk, f"connection closed after {answer!r}"
            answer += chunk
    return answer


def test_the_simulator_announces_serves_a_plain_socket_and_stops_cleanly(example_file: Path) -> None:
    thread, stop, port, announced = serve_in_thread(run_hexapod_simulator, example_file, "hexapod-sim-runner")
    try:
        assert _ask(port, b"CSV?\n") == b"2.0\n"
        assert _ask(port, b"SAI?\n") == b"X \nY \nZ \nU \nV \nW\n"
    finally:
        stop.set()
        thread.join(timeout=10.0)
    assert not thread.is_alive()
    assert announced == [f"listening 127.0.0.1:{port}"]


def test_wavestack_sim_hexapod_prints_one_line_and_stops_on_sigterm() -> None:
    command = [sys.executable, "-m", "wavestack.cli", "sim", "hexapod", "--port", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None
            line = process.stdout.readline().strip()  # arrives while the server runs: it was flushed
            assert line.startswith("listening 127.0.0.1:"), line
            port = int(line.rsplit(":", 1)[1])
            assert _ask(port, b"*IDN?\n").startswith(b"Physik Instrumente")
            assert _ask(port, b"\x07") == b"\xb1\n"
        finally:
            process.send_signal(signal.SIGTERM)
            stdout, stderr = process.communicate(timeout=20.0)
    assert process.returncode == 0, stderr
    assert stdout == ""  # exactly one line on stdout


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.10", "hexapod.example.com", "::"])
def test_a_non_loopback_host_is_refused_without_allow_remote(host: str) -> None:
    announced: list[str] = []
    with pytest.raises(ValueError, match="no authentication.*--allow-remote"):
        run_hexapod_simulator(None, host, 0, False, announced.append, threading.Event())
    assert announced == []


def test_a_bad_port_or_a_busy_one_is_bad_input() -> None:
    announced: list[str] = []
    with pytest.raises(ValueError, match="port must be 0..65535"):
        run_hexapod_simulator(None, "127.0.0.1", 70000, False, announced.append, threading.Event())
    with socket.create_server(("127.0.0.1", 0)) as busy:
        with pytest.raises(ValueError, match="cannot serve the hexapod simulator"):
            run_hexapod_simulator(None, "127.0.0.1", busy.getsockname()[1], False, announced.append,
                                  threading.Event())
    assert announced == []


def test_the_example_file_equals_the_built_in_hexapod(example_file: Path) -> None:
    assert hexapod_settings(load_hexapod_sim_config(example_file)) == HexapodSimSettings()
    assert hexapod_settings(load_hexapod_sim_config(None)) == HexapodSimSettings()


def test_a_field_stage_table_gives_two_axes_and_no_pivot() -> None:
    document = {"field_stage": {"url": "tcp://10.0.0.2:50000",  # the driver's keys are not ours to check
                                "simulator": {"axes": ["X", "Y"], "low_limits": [-40, -30],
                                              "high_limits": [40, 30], "velocity": 5}}}
    settings = parse_hexapod_sim_config(document, source="bench.toml", table="field_stage")
    assert settings.axes == ("X", "Y") and settings.pivot is None and settings.velocity == 5.0


@pytest.mark.parametrize(("table", "message"), [
    ({"velocty": 1.0}, "unknown key 'velocty'"),
    ({"axes": ["X", "Y"]}, r"\[hexapod.simulator\] low_limits: expected 2 finite values"),
    ({"velocity": 50.0}, r"velocity: expected 0 < velocity <= max_velocity"),
    ({"reference_time_s": -1.0}, "reference_time_s"),
])
def test_bad_simulator_tables_name_file_table_and_key(table: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as caught:
        hexapod_settings(parse_hexapod_sim_config({"hexapod": {"simulator": table}}, source="lab.toml"), source="lab.toml")
    assert "lab.toml" in str(caught.value)


def test_a_file_without_the_device_table_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"missing table \[hexapod\]"):
        parse_hexapod_sim_config({"plc": {}}, source="lab.toml")


def test_the_config_module_examples_run() -> None:
    import doctest

    from wavestack.config import hexapod_sim

    result = doctest.testmod(hexapod_sim)
    assert result.attempted > 0 and result.failed == 0
