"""The real-bench configuration pointed at a remote alignment bench (the shipped example with its addresses
replaced), and one trial: ``wavestack sim align-bench`` and ``wavestack align`` in two processes."""

from __future__ import annotations

import json
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "config" / "tma-alignment-remote.toml"
EXAMPLE_STATION = REPO / "config" / "tma-alignment-remote-station.toml"


def addresses(lines: list[str]) -> dict[str, str]:
    """``sim align-bench``'s announcements -> {"hexapod": url, "field_stage": url, "camera": url, "piezo": url}."""
    found = {}
    for line in lines:
        name, kind, where, *rest = line.split()
        if kind == "pty":
            found[name] = where
        elif name == "camera" or name == "piezo":
            found[name] = rest[0]
        else:
            found[name] = f"tcp://{where}"
    return found


def write_real_config(folder: Path, urls: dict[str, str], **align: object) -> Path:
    """Write the example (and its station file) into ``folder`` with ``urls`` and ``[align]`` overrides."""
    station = EXAMPLE_STATION.read_text(encoding="utf-8")
    station = re.sub(r'(?m)^url = "usbtcp://[^"]*"', f'url = "{urls["camera"]}"', station)
    station = re.sub(r'(?m)^url = "socket://[^"]*"', f'url = "{urls["piezo"]}"', station)
    (folder / EXAMPLE_STATION.name).write_text(station, encoding="utf-8")
    text = EXAMPLE.read_text(encoding="utf-8")
    text = text.replace('url = "tcp://127.0.0.1:50000"', f'url = "{urls["hexapod"]}"')
    text = text.replace('url = "tcp://127.0.0.1:50001"', f'url = "{urls["field_stage"]}"')
    for key, value in align.items():
        shown = str(value).lower() if isinstance(value, bool) else repr(value) if isinstance(value, str) else value
        text, count = re.subn(rf"(?m)^{key} = .*$", f"{key} = {shown}", text)
        if not count:
            text = text.replace("[align]\n", f"[align]\n{key} = {shown}\n", 1)
    path = folder / EXAMPLE.name
    path.write_text(text, encoding="utf-8")
    return path


WAVESTACK = [sys.executable, "-m", "wavestack.cli"]
DEVICES = 4  # hexapod, field stage, camera, piezo


def _read_lines(process: subprocess.Popen[str], count: int, timeout_s: float) -> list[str]:
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert process.stdout is not None
        for _ in range(count):
            line = process.stdout.readline()
            if not line:
                return
            lines.put(line.strip())

    reader = threading.Thread(target=pump, name="align-bench-lines")
    reader.start()
    got = []
    try:
        for _ in range(count):
            got.append(lines.get(timeout=timeout_s))
    except queue.Empty:
        pass
    finally:
        if len(got) < count:
            process.send_signal(signal.SIGINT)
        reader.join(timeout_s)
    return got


def trial(seed: int, folder: Path) -> dict[str, object]:
    """One alignment of the remote bench with mount seed ``seed``: the align summary, its iterations, the
    align command's exit status and wall time (s, its start-up included)."""
    bench = subprocess.Popen([*WAVESTACK, "sim", "align-bench", "--seed", str(seed), "--piezo-port", "0"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = _read_lines(bench, DEVICES, 120.0)
        assert len(lines) == DEVICES, (lines, bench.poll())
        config = write_real_config(folder, addresses(lines))
        started = time.perf_counter()
        done = subprocess.run([*WAVESTACK, "align", "--config", str(config), "--json"], capture_output=True,
                              text=True, timeout=600)
        seconds = time.perf_counter() - started
    finally:
        bench.send_signal(signal.SIGINT)
        _, err = bench.communicate(timeout=60)
    assert "stopped" in err, err[-2000:]
    records = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert records and records[-1]["type"] == "summary", (done.returncode, done.stderr[-2000:])
    return {"summary": records[-1], "iterations": [r for r in records if r["type"] == "iteration"],
            "returncode": done.returncode, "seconds": seconds}
