"""``wavestack sim pzt|plc`` as a user runs them: a real process, one announced line, a clean stop.

The announced endpoint is then used by our own drivers, the way any serial or Modbus tool would.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from wavestack.drivers.mdt693b import MDT693B
from wavestack.drivers.plc import PolishingLink
from wavestack.config.plc import load_plc_config

_START_TIMEOUT_S = 60.0


@contextmanager
def _simulator(*args: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    process = subprocess.Popen(
        [sys.executable, "-m", "wavestack.cli", "sim", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        line = process.stdout.readline().strip()  # flushed at once by the command, or EOF on failure
        yield process, line
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        process.stdout.close()
        process.stderr.close()


@pytest.mark.parametrize("stop_signal", [signal.SIGINT, signal.SIGTERM])
def test_sim_pzt_announces_a_pty_our_driver_can_open_and_stops_on_a_signal(stop_signal: int) -> None:
    with _simulator("pzt") as (process, line):
        assert line.startswith("pty /dev/"), line
        path = line.split(" ", 1)[1]
        assert os.path.exists(path)
        with MDT693B(path) as piezo:
            piezo.open(timeout_s=5.0)
            reading = piezo.set_voltage("x", 12.5, timeout_s=5.0)
            assert reading.readback_v == pytest.approx(12.5, abs=0.05)
        process.send_signal(stop_signal)
        assert process.wait(timeout=30) == 0
        assert "stopped" in process.stderr.read()


def test_sim_plc_announces_its_port_and_our_link_passes_the_self_check() -> None:
    with _simulator("plc", "--port", "0") as (process, line):
        host_port = line.removeprefix("listening ")
        assert line.startswith("listening 127.0.0.1:"), line
        host, port = host_port.rsplit(":", 1)
        config = load_plc_config(None)
        with PolishingLink(host, int(port), config.link.register_map()) as link:
            link.connect(timeout_s=5.0)
            assert link.self_check(timeout_s=5.0) == pytest.approx(12345.678, rel=1e-6)
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 0


def test_sim_plc_refuses_a_remote_host_without_allow_remote() -> None:
    result = subprocess.run([sys.executable, "-m", "wavestack.cli", "sim", "plc", "--host", "0.0.0.0"],
                            capture_output=True, text=True, timeout=_START_TIMEOUT_S)
    assert result.returncode == 2
    assert result.stdout == ""
    assert "--allow-remote" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_sim_plc_with_a_job_folder_runs_a_job_our_link_hands_it(tmp_path) -> None:
    import time

    import numpy as np

    from wavestack.drivers.plc import JobFile, MachineState, write_job_file

    with _simulator("plc", "--port", "0", "--job-folder", str(tmp_path)) as (process, line):
        assert line.startswith("listening 127.0.0.1:"), line
        host, port = line.removeprefix("listening ").rsplit(":", 1)
        config = load_plc_config(None)
        with PolishingLink(host, int(port), config.link.register_map(),
                           job_limits=config.link.job_limits()) as link:
            link.connect(timeout_s=5.0)
            link.self_check(timeout_s=5.0)
            link.heartbeat(timeout_s=5.0)
            assert link.read_machine(timeout_s=5.0).state is MachineState.IDLE
            job_id = link.next_job_id()
            n = 5
            job = JobFile(job_id, np.linspace(-1.0, 1.0, n), np.zeros(n), np.full(n, 0.01), np.full(n, 50.0), 0.25,
                          {"kind": "gaussian", "fwhm_mm": 4.0, "peak_rate_nm_s": 1.0}, {"pixels": 1})
            receipt = write_job_file(tmp_path, job)
            link.heartbeat(timeout_s=5.0)
            link.load_job(receipt, job_id)
            states = []
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline:
                link.heartbeat(timeout_s=5.0)
                status = link.read_machine(timeout_s=5.0)
                states.append(status.state)
                if status.state is MachineState.LOADED:
                    link.start_job(job_id)
                if status.state in (MachineState.DONE, MachineState.ABORTED, MachineState.FAULT):
                    break
                time.sleep(0.05)
            assert states[-1] is MachineState.DONE, (states, status)
            assert status.job_id == job_id and status.points_done == n
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 0
