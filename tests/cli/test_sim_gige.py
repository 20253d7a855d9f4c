"""``wavestack sim gige``: a simulated GigE Vision camera on its own, as a user starts it."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from wavestack.drivers.gige import GigECamera


def test_wavestack_sim_gige_serves_a_camera_the_driver_streams_from_and_stops_on_sigterm() -> None:
    command = [sys.executable, "-m", "wavestack.cli", "sim", "gige", "--port", "0"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None
            line = process.stdout.readline().strip()
            assert line.startswith("listening 127.0.0.1:"), line
            with GigECamera.open(f"gige://{line.split()[1]}", timeout_s=5.0) as camera:
                shape = (camera.height, camera.width)
                camera.start()
                frame = camera.read_frame(10.0)
                camera.stop()
            assert frame.pixels.shape == shape and frame.pixels.max() > 0  # the optic's fringes
        finally:
            process.send_signal(signal.SIGTERM)
            _, errors = process.communicate(timeout=30)
    assert process.returncode == 0, errors
    assert "stopped" in errors


@pytest.mark.parametrize(("arguments", "message"), [
    (["--host", "0.0.0.0"], "no authentication"), (["--vendor", "flir-bfs"], "go together"),
    (["--port", "70000"], "port"),
])
def test_bad_arguments_are_one_line(arguments: list[str], message: str) -> None:
    done = subprocess.run([sys.executable, "-m", "wavestack.cli", "sim", "gige", *arguments], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and message in done.stderr and len(done.stderr.strip().splitlines()) == 1
