"""``--web`` on ``run``, ``polish`` and ``align``: the checks before any device, and what a browser receives.

The loops' pages are read over the WebSocket as a browser would (the page itself is tested in
Chromium by test_browser.py): every message until the command ends and the server closes.
"""

from __future__ import annotations

import asyncio
import json
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import aiohttp
import pytest

from polishing_stations import polishing_text
from wavestack.cli import main

WAVESTACK = [sys.executable, "-m", "wavestack.cli"]


def _main(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    try:
        status = main(list(args))
    except SystemExit as stopped:  # argparse's usage errors
        status = int(stopped.code or 0)
    return status, capsys.readouterr().err


@pytest.mark.parametrize("command", ["run", "polish", "align"])
def test_a_remote_address_is_refused_without_allow_remote_before_any_device(
        capsys: pytest.CaptureFixture[str], command: str) -> None:
    status, err = _main(capsys, command, "--web", "--web-host", "0.0.0.0", "--web-port", "0")
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert "--web-host 0.0.0.0: refusing to serve the web view" in err and "--allow-remote" in err


def test_a_busy_port_and_a_bad_port_are_one_line_errors(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        status, err = _main(capsys, "run", "--web", "--web-port", str(busy.getsockname()[1]))
    assert status == 2 and "cannot serve the web view" in err and "--web-port 0" in err, err
    status, err = _main(capsys, "run", "--web", "--web-port", "70000")
    assert status == 2 and "--web-port: expected a port 0..65535" in err, err


def _url(stderr: Path, process: subprocess.Popen) -> str:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and process.poll() is None:
        found = re.search(r"^web view: (http://127\.0\.0\.1:\d+/)$", stderr.read_text(), re.M)
        if found:
            return found.group(1)
        time.sleep(0.02)
    raise AssertionError(f"no web view URL on stderr: {stderr.read_text()}")


def _watch(tmp_path: Path, *args: str) -> tuple[list[dict], list[dict]]:
    """Run ``wavestack ARGS --web --web-port 0 --json``; (every WebSocket message, the JSON lines)."""
    stdout, stderr = tmp_path / "out.jsonl", tmp_path / "err.txt"
    with stdout.open("w") as out, stderr.open("w") as err:
        process = subprocess.Popen([*WAVESTACK, *args, "--web", "--web-port", "0", "--json"], stdout=out, stderr=err)
    try:
        url = _url(stderr, process)

        async def collect() -> list[dict]:
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(url.replace("http", "ws") + "ws") as ws:
                    return [json.loads(message.data) async for message in ws]

        messages = asyncio.run(asyncio.wait_for(collect(), 240))
        assert process.wait(timeout=60) == 0, stderr.read_text()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return messages, [json.loads(line) for line in stdout.read_text().splitlines()]


def _latest(messages: list[dict], key: str) -> dict:
    """The newest full ``key`` section (maps and tables are sent once, then only their seq)."""
    return next(m[key] for m in reversed(messages) if m[key] and len(m[key]) > 1)


@pytest.mark.slow
def test_align_shows_each_field_map_and_the_iterations(tmp_path: Path) -> None:
    messages, lines = _watch(tmp_path, "align", "--max-iterations", "1")
    iterations = [line for line in lines if line["type"] == "iteration"]
    history = _latest(messages, "history")
    assert history["kind"] == "align" and [row[0] for row in history["rows"]] == [i["iteration"] for i in iterations]
    for row, iteration in zip(history["rows"], iterations):
        assert row[1] == pytest.approx(max(iteration["rms_waves"]), rel=1e-12)
    assert history["trend"] == pytest.approx([max(i["rms_waves"]) for i in iterations], rel=1e-12)
    maps = [m["map"] for m in messages if m["map"] and "png" in m["map"]]
    assert maps and all(re.fullmatch(r"wavefront at field point \d", m["title"]) for m in maps)
    assert maps[-1]["units"] == "waves" and maps[-1]["outline"]
    assert messages[-1]["state"] == "stopped" and messages[-1]["detail"].startswith(lines[-1]["final_phase"])


@pytest.mark.slow
def test_polish_shows_the_station_and_the_runs(tmp_path: Path) -> None:
    config = tmp_path / "polishing.toml"
    config.write_text(polishing_text(small=True))
    messages, lines = _watch(tmp_path, "polish", "--config", str(config), "--max-runs", "1", "--target-rms-nm", "0")
    (run,) = [line for line in lines if line["type"] == "run"]
    history = _latest(messages, "history")
    assert history["kind"] == "polish" and history["rows"][0][:2] == [run["run"], run["job_id"]]
    assert history["rows"][0][4] == pytest.approx(run["measured_rms_nm"], rel=1e-12)
    assert history["trend"] == pytest.approx(lines[-1]["rms_nm"], rel=1e-12)
    station = next(m["station"] for m in reversed(messages) if m["station"])
    assert station["results"] > 0 and station["plc_state"] and station["fitter"] != "-"
    assert any(m["map"] and "png" in m["map"] for m in messages)
    assert messages[-1]["state"] == "stopped" and messages[-1]["detail"].startswith("max-runs")
