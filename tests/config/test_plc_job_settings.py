"""PLC job settings: the job blocks, the host's job limits, ``[plc.simulator.machine]``, and
``wavestack sim plc`` with a machine on a job folder."""

from __future__ import annotations

import queue
import re
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from wavestack.cli.sim_plc import run_plc_simulator
from wavestack.config.plc import load_plc_config
from wavestack.config.schema import ConfigError
from wavestack.drivers.plc import JobFile, MachineState, PolishingLink, write_job_file
from wavestack.simulated import machine_settings, plc_layout

MINIMAL = '[plc]\nurl = "tcp://10.0.0.5:502"\n'


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plc.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_defaults_carry_the_job_blocks_and_limits() -> None:
    config = load_plc_config(None)
    register_map, layout = config.link.register_map(), plc_layout(config)
    assert register_map.job is not None and register_map.machine is not None
    assert (register_map.job.start, register_map.machine.start) == (layout.job_register, layout.machine_register)
    assert register_map.job.word_order == layout.job_order
    assert config.link.job_limits().max_points == 500_000


def test_the_machine_table_and_its_job_folder(tmp_path: Path) -> None:
    config = load_plc_config(write(tmp_path, MINIMAL + 'job_folder = "/host/jobs"\n[plc.simulator.polishing]\n'
                                   "[plc.simulator.machine]\ntime_scale = 50.0\nwidth_error = 0.1\n"))
    settings = machine_settings(config)
    assert (settings.job_folder, settings.time_scale, settings.width_error) == (Path("/host/jobs"), 50.0, 0.1)
    assert machine_settings(config, tmp_path).job_folder == tmp_path  # an explicit folder wins
    bare = load_plc_config(write(tmp_path, MINIMAL + "[plc.simulator.polishing]\n"))
    with pytest.raises(ConfigError, match="needs a job folder"):
        machine_settings(bare)


@pytest.mark.parametrize(("text", "message"), [
    (MINIMAL + "job_travel_x_mm = [5.0, -5.0]\n", r"job limits: travel_x_mm"),
    (MINIMAL + "job_max_feed_mm_s = 0.0\n", r"job_max_feed_mm_s: expected >= 0.001"),
    (MINIMAL + "[plc.simulator.polishing]\n[plc.simulator.machine]\ntravel_y_mm = [1.0, 1.0]\n", r"travel_y_mm"),
    (MINIMAL + "[plc.simulator.machine]\nspeed = 3\n", r"unknown key 'speed'"),
    (MINIMAL + "job_register = 100\n", r"overlaps"),
])
def test_bad_job_settings_are_refused(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_plc_config(write(tmp_path, text))


def test_sim_plc_runs_jobs_with_a_machine_on_a_job_folder(tmp_path: Path) -> None:
    lines: queue.Queue[str] = queue.Queue()
    stop = threading.Event()
    runner = threading.Thread(target=run_plc_simulator, args=(None, "127.0.0.1", 0, False, lines.put, stop),
                              kwargs={"job_folder": tmp_path}, name="plc-sim-machine")
    runner.start()
    try:
        line = lines.get(timeout=10.0)
        match = re.fullmatch(r"listening 127\.0\.0\.1:(\d+)", line)  # exactly the line scripts parse
        assert match is not None, line
        port = int(match.group(1))
        config = load_plc_config(None)
        with PolishingLink("127.0.0.1", port, config.link.register_map(), config.link.link_timing(),
                           job_limits=config.link.job_limits()) as link:
            link.connect(timeout_s=2.0)
            link.self_check(timeout_s=1.0)
            job = JobFile(1, np.zeros(3), np.zeros(3), np.full(3, 0.5), np.full(3, 10.0), 0.1, {}, {})
            link.load_job(write_job_file(tmp_path, job), 1)
            link.start_job(1)
            deadline = time.monotonic() + 20.0
            while link.read_machine().state is not MachineState.DONE and time.monotonic() < deadline:
                link.heartbeat(timeout_s=1.0)
                time.sleep(0.01)
            assert link.read_machine().points_done == 3
    finally:
        stop.set()
        runner.join(10.0)
    assert not runner.is_alive()
