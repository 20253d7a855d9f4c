"""What the live web view costs: a map render, the station's sink call, and the station's rate with ``--web``.

Run:  .venv/bin/python benchmarks/bench_web.py [--rounds 50] [--station-s 20] [--pairs 2]

1. ``render_map`` on a 512 x 512 annulus (the default station's fit grid: 1024 px, decimation 2),
   smooth wavefront plus 0.005 waves of noise: minimum and median ms, PNG bytes.
2. ``LiveFeed.__call__`` (what the pipeline thread pays per result): median microseconds.
3. ``wavestack run`` on the small test station for ``--station-s`` seconds, without and with
   ``--web --web-port 0`` and a browser-like WebSocket reader, interleaved ``--pairs`` times:
   results per second from the summary, and the ratio with/without (a ratio survives a loaded
   machine; absolute rates do not). ``--pairs 0`` skips it.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import aiohttp
import numpy as np

from wavestack.station import Counters, CycleRecord, StationResult
from wavestack.web import LiveFeed, render_map

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "tests" / "configs" / "station-small.toml"


def _annulus_map() -> np.ndarray:
    y, x = np.mgrid[-1:1:512j, -1:1:512j]
    r2 = x * x + y * y
    noise = 0.005 * np.random.default_rng(1).standard_normal(r2.shape)
    wavefront = 0.35 * np.sqrt(3) * (2 * r2 - 1) + 0.12 * x * y + noise
    return np.where((r2 < 0.86) & (r2 > 0.06), wavefront, np.nan)


def bench_render(rounds: int) -> None:
    values = _annulus_map()
    times = [render_map(values, units="waves", title="bench", seq=1).render_ms for _ in range(rounds)]
    image = render_map(values, units="waves", title="bench", seq=1)
    print(f"render_map 512x512 -> {image.width}x{image.height}: min {min(times):.1f} ms, "
          f"median {statistics.median(times):.1f} ms over {rounds}; PNG {len(image.png)} bytes")


def bench_sink(calls: int = 2000) -> None:
    feed = LiveFeed("bench")
    values = _annulus_map()
    record = CycleRecord(StationResult.invalid(0, "", Counters.zero(5), ordering="noll"), waves=values)
    times = []
    for _ in range(calls):
        started = time.perf_counter_ns()
        feed(record)
        times.append(time.perf_counter_ns() - started)
    print(f"LiveFeed sink call: median {statistics.median(times) / 1e3:.1f} us over {calls}")


async def _read_ws(url: str) -> int:
    count = 0
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url.replace("http", "ws") + "ws") as ws:
            async for _ in ws:
                count += 1
    return count


def _station_rate(seconds: float, web: bool) -> tuple[float, int]:
    """(results per second, WebSocket messages read) of one run."""
    command = [sys.executable, "-m", "wavestack.cli", "run", "--config", str(SMALL), "--json",
               "--duration", str(seconds)] + (["--web", "--web-port", "0"] if web else [])
    with tempfile.TemporaryDirectory() as folder:
        out, err = Path(folder) / "out", Path(folder) / "err"
        with out.open("w") as o, err.open("w") as e:
            process = subprocess.Popen(command, stdout=o, stderr=e)
        messages = 0
        if web:
            while not (found := re.search(r"web view: (\S+)", err.read_text())):
                time.sleep(0.02)
            messages = asyncio.run(_read_ws(found.group(1)))
        process.wait()
        summary = json.loads(out.read_text().splitlines()[-1])
    return summary["results_per_s"], messages


def bench_station(seconds: float, pairs: int) -> None:
    without, with_web = [], []
    for _ in range(pairs):
        without.append(_station_rate(seconds, False)[0])
        rate, messages = _station_rate(seconds, True)
        with_web.append(rate)
        print(f"  pair: {without[-1]:.2f} results/s without, {rate:.2f} with --web ({messages} updates read)")
    ratio = statistics.median(w / o for w, o in zip(with_web, without))
    print(f"station (small test config, {seconds:g} s runs, {pairs} pairs): "
          f"median ratio with/without --web {ratio:.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=50)
    parser.add_argument("--station-s", type=float, default=20.0)
    parser.add_argument("--pairs", type=int, default=2)
    args = parser.parse_args()
    bench_render(args.rounds)
    bench_sink()
    if args.pairs:
        bench_station(args.station_s, args.pairs)


if __name__ == "__main__":
    main()
