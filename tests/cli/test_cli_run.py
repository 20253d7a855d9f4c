"""``wavestack run`` and ``wavestack replay`` as a user runs them: real processes, real devices
(simulated), JSON lines, a clean stop on SIGTERM with the recording intact, and one-line errors."""

from __future__ import annotations

import importlib.resources
import json
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from wavestack.config import DEFAULT_CONFIG
from wavestack.recording import RecordingReader

ROOT = Path(__file__).resolve().parents[2]
SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
WAVESTACK = [sys.executable, "-m", "wavestack.cli"]
REQUIRED = {"frame_ids", "latency_ms", "coefficients", "ordering", "residual_rms", "residual_pv", "fitter",
            "counters", "truth_error_rms", "truth_rms"}


def _run(*args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*WAVESTACK, *args], capture_output=True, text=True, timeout=timeout)


def test_json_prints_one_object_per_result_then_a_summary_and_nothing_else() -> None:
    done = _run("run", "--config", str(SMALL), "--frames", "3", "--json")
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]  # every line is JSON
    assert [line["type"] for line in lines] == ["result"] * 3 + ["summary"]
    for result in lines[:3]:
        assert REQUIRED <= set(result), REQUIRED - set(result)
        assert len(result["frame_ids"]) == 5 and result["ordering"] == "noll"
        assert result["residual_pv"] > result["residual_rms"] > 0  # waves, like the rms
    for line in lines:  # every result and the summary: frames and sets apart, each adding up
        counters = line["counters"]
        frames, sets = counters["frames"], counters["sets"]
        assert counters["frames_per_set"] == 5
        assert frames["acquired"] == frames["processed"] + frames["dropped"] + frames["pending"], frames
        assert sets["assembled"] == sets["processed"] + sets["dropped"] + sets["pending"], sets
    assert [r["counters"]["sets"]["processed"] for r in lines[:3]] == [1, 2, 3]
    assert [r["counters"]["frames"]["processed"] for r in lines[:3]] == [5, 10, 15]
    assert lines[-1]["results"] == 3 and lines[-1]["counters"]["sets"]["processed"] == 3


def test_the_live_view_and_summary_on_a_plain_stdout() -> None:
    done = _run("run", "--config", str(SMALL), "--frames", "2")
    assert done.returncode == 0, done.stderr
    assert "latency p50" in done.stdout and "2 results (2 valid)" in done.stdout
    out = done.stdout.splitlines()
    summary = out[next(k for k, line in enumerate(out) if line.startswith("2 results (2 valid) in ")):]
    assert summary[1].startswith("frames acquired ") and " = 10 in processed sets + " in summary[1]
    assert summary[2].startswith("sets of 5 assembled ") and " = 2 processed + " in summary[2]
    assert "fit residual: rms " in done.stdout  # the live view's last block
    assert "\x1b[" not in done.stdout  # no cursor movement when stdout is not a terminal


def test_sigterm_stops_cleanly_with_the_recording_flushed_and_replayable(tmp_path: Path) -> None:
    record = tmp_path / "run.h5"
    process = subprocess.Popen([*WAVESTACK, "run", "--config", str(SMALL), "--json", "--record", str(record)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        seen = [json.loads(process.stdout.readline()) for _ in range(3)]
        process.send_signal(signal.SIGTERM)
        rest, errors = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, errors
    tail = [json.loads(line) for line in rest.splitlines()]
    assert all(r["type"] == "result" for r in seen) and tail[-1]["type"] == "summary"
    results = tail[-1]["results"]
    with RecordingReader(record) as reader:
        assert reader.closed_cleanly
        assert reader.n_results == results and reader.n_sets == results
        assert "[processing]" in reader.config_toml and reader.conventions["ordering"] == "noll"

    replayed = _run("replay", str(record), "--json")
    assert replayed.returncode == 0, replayed.stderr
    lines = [json.loads(line) for line in replayed.stdout.splitlines()]
    assert lines[-1]["results"] == results and lines[-1]["compared"] == results
    assert lines[-1]["max_difference_rms"] <= 1e-12  # same frames, same fitters: the same numbers
    assert lines[-1]["compared_residual_pv"] == results and lines[-1]["max_residual_pv_difference"] <= 1e-12


def test_a_config_that_does_not_validate_is_one_line_naming_file_and_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(SMALL.read_text().replace("modes = 36", "modes = 36\nmodez = 4"))
    done = _run("run", "--config", str(bad), "--frames", "1")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "bad.toml: [processing] unknown key 'modez'" in done.stderr


def test_a_device_that_cannot_be_reached_is_one_line_naming_it() -> None:
    # The hardware example asks for a real USB camera: a test machine has no libusb ("USB3 Vision
    # camera: pyusb found no USB backend") or no camera plugged in ("U3V camera: expected a USB3
    # Vision device ... found none").
    done = _run("run", "--config", str(ROOT / "config" / "station-hardware.example.toml"), "--frames", "1")
    assert done.returncode == 3 and done.stdout == ""
    assert done.stderr.count("\n") == 1
    assert "USB3 Vision camera: pyusb found no USB backend" in done.stderr or "U3V camera" in done.stderr


def test_there_is_one_default_station_file_and_the_package_ships_it() -> None:
    # the one copy lives in the package (wavestack/config/default.toml), none in the config folder
    assert not (ROOT / "config" / "default.toml").exists()
    shipped = importlib.resources.files("wavestack.config") / "default.toml"
    assert shipped.read_text(encoding="utf-8") == DEFAULT_CONFIG.read_text(encoding="utf-8")
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "*.toml" in package_data["wavestack.config"]  # so a wheel carries it too


@pytest.mark.parametrize("args", [["--frames", "0"], ["--duration", "-1"], ["--frames", "2", "--duration", "1"]])
def test_bad_limits_are_usage_errors(args: list[str]) -> None:
    done = _run("run", *args)
    assert done.returncode == 2 and done.stdout == ""
