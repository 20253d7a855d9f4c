"""The standalone PLC simulator (``wavestack sim plc``) and its watchdog and fault switches."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from sim_serving import serve_in_thread
from wavestack.config.schema import ConfigError
from wavestack.drivers.plc import PolishingLink, decode_float32, round_to_float32
from wavestack.config.plc import load_plc_config
from wavestack.cli.bind import is_loopback
from wavestack.cli.sim_plc import run_plc_simulator
from wavestack.simulators.plc import HeartbeatWatchdog, SimFaults, WatchdogState

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


def _serve(config: Path | None) -> tuple[threading.Thread, threading.Event, int, list[str]]:
    """Run the simulator in a thread; returns the thread, its stop event, the port and every announcement."""
    return serve_in_thread(run_plc_simulator, config, "plc-sim-runner")


@pytest.mark.parametrize("config", [None, CONFIG_DIR / "plc-sim.toml"])
def test_the_simulator_serves_the_driver_and_stops_cleanly(config: Path | None) -> None:
    thread, stop, port, announced = _serve(config)
    settings = load_plc_config(config).link
    try:
        assert port > 0
        with PolishingLink("127.0.0.1", port, settings.register_map(), settings.link_timing()) as link:
            link.connect(timeout_s=2.0)
            assert link.self_check(timeout_s=1.0) == round_to_float32(settings.self_check_value)
            removal = [1.0] * settings.n_terms
            assert link.send_removal(1, removal, passes=1, timeout_s=2.0).status.last_accepted_id == 1
    finally:
        stop.set()
        thread.join(timeout=10.0)
    assert not thread.is_alive()
    assert announced == [f"listening 127.0.0.1:{port}"]


def test_any_modbus_tool_can_read_the_standalone_simulator() -> None:
    """``wavestack sim plc`` prints one flushed line, serves a plain pymodbus client, stops on SIGTERM."""
    command = [sys.executable, "-m", "wavestack.cli", "sim", "plc", "--port", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None
            line = process.stdout.readline().strip()  # arrives while the server runs: it was flushed
            assert line.startswith("listening 127.0.0.1:"), line
            client = ModbusTcpClient("127.0.0.1", port=int(line.rsplit(":", 1)[1]), timeout=2.0, retries=0)
            try:
                assert client.connect()
                registers = client.read_holding_registers(0, count=2, device_id=1).registers
            finally:
                client.close()
            settings = load_plc_config(None).link
            assert decode_float32(registers, settings.word_order) == round_to_float32(settings.self_check_value)
        finally:
            process.send_signal(signal.SIGTERM)
            _, stderr = process.communicate(timeout=20.0)
    assert process.returncode == 0, stderr


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.10", "plc.example.com", "::"])
def test_a_non_loopback_host_is_refused_without_allow_remote(host: str) -> None:
    announced: list[str] = []
    with pytest.raises(ValueError, match="no authentication.*--allow-remote"):
        run_plc_simulator(None, host, 0, False, announced.append, threading.Event())
    assert announced == []


def test_loopback_hosts_are_recognised() -> None:
    assert all(is_loopback(h) for h in ("127.0.0.1", "127.1.2.3", "::1", "localhost"))
    assert not any(is_loopback(h) for h in ("0.0.0.0", "10.0.0.1", "::", "example.com"))


def test_a_config_without_simulator_table_is_refused(tmp_path: Path) -> None:
    announced: list[str] = []
    with pytest.raises(ConfigError, match=r"no \[plc.simulator\] table"):
        run_plc_simulator(CONFIG_DIR / "plc-example.toml", "127.0.0.1", 0, False, announced.append,
                          threading.Event())
    with pytest.raises(ValueError, match="port must be 0..65535"):
        run_plc_simulator(None, "127.0.0.1", 70000, False, announced.append, threading.Event())
    assert announced == []


def test_a_busy_port_is_reported_as_bad_input() -> None:
    thread, stop, port, _ = _serve(None)
    try:
        with pytest.raises(ValueError, match=f"cannot serve the PLC simulator on 127.0.0.1:{port}"):
            run_plc_simulator(None, "127.0.0.1", port, False, lambda line: None, threading.Event())
    finally:
        stop.set()
        thread.join(timeout=10.0)
    assert not thread.is_alive()


def test_watchdog_counts_only_changes_and_stays_tripped_until_rearmed() -> None:
    timeout_s = 1.0
    watchdog = HeartbeatWatchdog(timeout_s, initial_value=7)
    assert not watchdog.observe(7, 0.0) and watchdog.state is WatchdogState.IDLE  # same value: no activity
    assert not watchdog.poll(100.0)  # idle never trips
    assert watchdog.observe(8, 100.0) and watchdog.state is WatchdogState.RUNNING
    assert not watchdog.observe(8, 100.9)  # rewriting the value does not feed the watchdog
    assert not watchdog.poll(100.0 + timeout_s)  # exactly the timeout is still alive ...
    assert watchdog.poll(100.0 + timeout_s + 1e-6)  # ... a moment later it trips, once
    assert not watchdog.poll(200.0) and watchdog.trips == 1
    assert not watchdog.observe(9, 200.0) and watchdog.state is WatchdogState.TRIPPED  # beats do not re-arm
    assert watchdog.rearm(200.0) and watchdog.state is WatchdogState.RUNNING
    assert not watchdog.rearm(200.1)  # re-arming a running watchdog changes nothing
    assert not watchdog.poll(200.0 + timeout_s) and watchdog.poll(200.0 + timeout_s + 0.5)
    assert watchdog.trips == 2
    with pytest.raises(ValueError, match="timeout_s"):
        HeartbeatWatchdog(0.0)


def test_reply_faults_hit_the_next_replies_of_their_function_code() -> None:
    faults = SimFaults()
    read_reply = bytes([0, 1, 0, 0, 0, 5, 1, 3, 2, 0, 42])  # MBAP + FC3 + byte count + one register
    write_reply = bytes([0, 2, 0, 0, 0, 6, 1, 6, 0, 10, 0, 1])
    faults.drop_replies(1, function_code=6)
    faults.truncate_replies(2, keep_bytes=9)
    assert faults.pending_reply_faults == 3
    assert faults.apply_to_reply(read_reply) == read_reply[:9]  # the FC6 drop waits for an FC6 reply
    assert faults.apply_to_reply(write_reply) == b""
    assert faults.apply_to_reply(write_reply) == write_reply[:9]
    assert faults.apply_to_reply(read_reply) == read_reply and faults.pending_reply_faults == 0
    faults.corrupt_replies()
    corrupted = faults.apply_to_reply(read_reply)
    assert corrupted[7] == 0x7F and corrupted[:7] + corrupted[8:] == read_reply[:7] + read_reply[8:]
    faults.delay_s, faults.estop = 1.0, True
    faults.clear()
    assert (faults.delay_s, faults.estop, faults.freeze_heartbeat_echo) == (0.0, False, False)
    with pytest.raises(ValueError, match="n must be >= 1"):
        faults.drop_replies(0)
