"""``wavestack plc status|rearm``: an operator's second Modbus client while a station's link beats."""

from __future__ import annotations

import socket
import time
from dataclasses import replace
from pathlib import Path

import pytest

from wavestack.cli import EXIT_BAD_INPUT, EXIT_DEVICE_ERROR, main
from wavestack.config import load_plc_config
from wavestack.drivers.plc import PolishingLink, ResultDisplay, SpecCode
from wavestack.simulated import plc_layout, polishing_station
from wavestack.simulators.plc import PlcSimulator, WatchdogState


def _simulator(watchdog_timeout_s: float) -> PlcSimulator:
    config = load_plc_config(None)
    layout = plc_layout(config)
    return PlcSimulator(replace(layout, watchdog_timeout_s=watchdog_timeout_s), polishing_station(config))


def _wait_for(condition, timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return condition()


def test_status_and_rearm_from_a_second_client_while_the_station_link_is_connected(capsys) -> None:
    settings = load_plc_config(None).link
    with _simulator(watchdog_timeout_s=0.5) as sim, \
            PolishingLink("127.0.0.1", sim.port, settings.register_map(), settings.link_timing()) as station:
        url = f"tcp://127.0.0.1:{sim.port}"
        station.connect(timeout_s=2.0)
        station.heartbeat(timeout_s=1.0)
        station.show_result(ResultDisplay(12, True, 3.21, 45.6, SpecCode.FAIL, "IRR"), timeout_s=1.0)
        assert main(["plc", "status", "--url", url]) == 0
        line = capsys.readouterr().out
        assert line.count("\n") == 1 and "READY" in line and f"127.0.0.1:{sim.port}" in line
        assert "; panel: result 12 valid, residual RMS 3.21 nm, PVr 45.6 nm, FAIL (limiting IRR)" in line
        assert _wait_for(lambda: sim.watchdog_state is WatchdogState.TRIPPED)  # the station's host stalls
        assert main(["plc", "status", "--url", url]) == 0
        assert "TRIPPED" in capsys.readouterr().out
        beat = sim.heartbeat_value
        assert main(["plc", "rearm", "--url", url]) == 0
        out = capsys.readouterr().out
        assert out.count("\n") == 1 and "re-armed" in out
        assert sim.heartbeat_value == beat  # the monitor wrote no heartbeat: the station owns it
        assert sim.connections >= 4  # the station's link and one per command, alongside
        status = station.heartbeat(timeout_s=1.0)  # the station's link goes on, on its own connection
        assert status.ready and not status.watchdog_tripped


def test_a_station_config_on_the_simulated_plc_asks_for_the_url(capsys) -> None:
    config = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
    assert main(["plc", "status", "--config", str(config)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--url tcp://127.0.0.1:PORT" in err


@pytest.mark.parametrize("action", ["status", "rearm"])
def test_no_plc_is_a_device_error_in_one_line(action: str, capsys) -> None:
    with socket.socket() as probe:  # a port nobody listens on once the probe is closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    assert main(["plc", action, "--url", f"tcp://127.0.0.1:{port}", "--timeout", "0.3"]) == EXIT_DEVICE_ERROR
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and f"127.0.0.1:{port}" in captured.err


def test_a_bad_url_names_it(capsys) -> None:
    assert main(["plc", "status", "--url", "udp://x"]) == EXIT_BAD_INPUT
    assert "udp://x" in capsys.readouterr().err


def test_the_panel_line_names_an_invalid_result_and_a_missing_verdict() -> None:
    from wavestack.cli.plc import describe_display
    from wavestack.drivers.plc import invalid_display

    assert describe_display(invalid_display(7, has_spec=True)) == "panel: result 7 INVALID, not judged"
    assert describe_display(ResultDisplay(8, True, 2.5, None, SpecCode.NO_SPEC)) == (
        "panel: result 8 valid, residual RMS 2.5 nm, no spec")
