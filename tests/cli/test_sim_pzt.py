"""``run_pzt_simulator``: serves a pty the driver can open, stops on request, leaves nothing behind."""

from __future__ import annotations

import os
import queue
import threading
from pathlib import Path

import pytest

from wavestack.config.schema import ConfigError
from wavestack.drivers.mdt693b import MDT693B
from wavestack.cli.sim_pzt import run_pzt_simulator


def _serve(config: Path | None) -> tuple[threading.Thread, threading.Event, str, list[str]]:
    """Start the simulator in a thread; returns the thread, its stop event, the pty path, all announcements."""
    lines: queue.Queue[str] = queue.Queue()
    announced: list[str] = []
    stop = threading.Event()

    def announce(line: str) -> None:
        announced.append(line)
        lines.put(line)

    thread = threading.Thread(target=run_pzt_simulator, args=(config, announce, stop), name="pzt-sim-runner")
    thread.start()
    try:
        line = lines.get(timeout=10.0)
    except queue.Empty:
        stop.set()
        thread.join()
        raise AssertionError("the simulator announced nothing") from None
    assert line.startswith("pty /dev/")
    return thread, stop, line.removeprefix("pty "), announced


def test_default_simulator_serves_the_driver_and_stops_cleanly() -> None:
    thread, stop, path, announced = _serve(None)
    try:
        with MDT693B(path, axes=("x", "y", "z")) as piezo:
            assert piezo.identity.model == "MDT693B"
            assert piezo.vlimit_v == 150.0
            assert piezo.set_voltage("y", 21.5, timeout_s=1.0).readback_v == 21.5
    finally:
        stop.set()
        thread.join(timeout=10.0)
    assert not thread.is_alive()
    assert announced == [f"pty {path}"]
    assert not os.path.exists(path)  # both pty descriptors closed: the slave node is gone


def test_configured_personality_is_served(tmp_path: Path) -> None:
    config = tmp_path / "pzt.toml"
    config.write_text('[pzt]\nurl = "sim://mdt693b"\nvolts_per_radian = 1.0\nbias_v = 10.0\n'
                      '[pzt.simulator]\nmodel = "MDT694B"\nprompt = "*"\necho = false\nvlimit_v = 75\n',
                      encoding="utf-8")
    thread, stop, path, _ = _serve(config)
    try:
        with MDT693B(path) as piezo:
            assert piezo.identity.model == "MDT694B"
            assert piezo.limits("x").max_v == 75.0
    finally:
        stop.set()
        thread.join(timeout=10.0)
    assert not thread.is_alive()


def test_bad_config_fails_before_serving(tmp_path: Path) -> None:
    config = tmp_path / "bad.toml"
    config.write_text('[pzt]\nurl = "sim://mdt693b"\nvolts_per_radian = 1.0\nbias_v = 10.0\n'
                      "[pzt.simulator]\nvlimit_v = 80\n", encoding="utf-8")
    announced: list[str] = []
    with pytest.raises(ConfigError, match="vlimit_v"):
        run_pzt_simulator(config, announced.append, threading.Event())
    assert announced == []
