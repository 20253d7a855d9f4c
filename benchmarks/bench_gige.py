"""GigE Vision streaming on loopback: 1024 x 1024 Mono12 at the simulated camera's rate, with and without loss.

Run:  .venv/bin/python benchmarks/bench_gige.py [--seconds 20] [--rates 30 45] [--loss 0 0.01]

The simulated camera runs in a child process (its own interpreter, as a camera is its own
device), streaming at a 1 Gbit/s link's pace with 8192-byte packets (jumbo frames, which loopback
carries); the driver runs here with an oldest-first ring, so every frame the camera sent is
delivered to this loop or counted dropped. Each image is one of 16 patterns chosen by its block id: a frame
assembled from two blocks, or with a hole filled by another block's bytes, fails the check.
For each rate and loss fraction it prints the frames the camera sent, those its free-run clock
passed while it was busy sending (``unsent``: the simulated camera's own limit on a loaded
machine), delivered, lost (sent and not delivered), the ring's dropped count (gaps: unsent and
lost blocks), torn (must be 0), blocks the driver gave up after its resend rounds, resend requests, packets the camera's loss switch ate, the
delivered rate, and the machine's load before the run.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import time
from typing import Any

import numpy as np

from wavestack.drivers.gige import GigECamera
from wavestack.drivers.ring import RingPolicy

SIZE = 1024
KINDS = 16  # distinct images, block id modulo 16: a frame mixing two neighbouring blocks cannot match either


def patterns() -> list[np.ndarray]:
    rows, cols = np.indices((SIZE, SIZE))
    return [((rows * 7 + cols * 3 + kind * 211) % 4096).astype(np.uint16) for kind in range(KINDS)]


def _serve(rate: float, loss: float, ready: Any, stop: Any) -> None:
    from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera

    images = patterns()  # rendered once: the benchmark measures the transport, not the optic

    def render(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, None]:
        return images[block_id % KINDS], None

    settings = GigESimSettings(width=SIZE, height=SIZE, pixel_format="Mono12", frame_rate_hz=rate,
                               link_rate_mbit_s=1000.0, heartbeat_timeout_ms=5000)
    with SimulatedGigECamera(settings, render) as camera:
        camera.faults.packet_loss = loss
        ready.send((camera.host, camera.port))
        stop.wait()
        ready.send(dict(camera.counters))


def run(rate: float, loss: float, seconds: float) -> dict[str, float]:
    context = multiprocessing.get_context("spawn")
    parent, child = context.Pipe()
    stop = context.Event()
    process = context.Process(target=_serve, args=(rate, loss, child, stop), daemon=True)
    process.start()
    host, port = parent.recv()
    torn = delivered = 0
    images = patterns()
    with GigECamera.open(f"gige://{host}:{port}", timeout_s=5.0, ring_capacity=16,
                         ring_policy=RingPolicy.OLDEST_FIRST) as camera:
        camera.start()
        started = time.monotonic()
        first = last = None
        while time.monotonic() - started < seconds:
            frame = camera.read_frame(5.0)
            first = frame.frame_id if first is None else first
            last = frame.frame_id
            delivered += 1
            torn += not np.array_equal(frame.pixels, images[frame.frame_id % KINDS])
        elapsed = time.monotonic() - started
        camera.stop()
        counters = camera.counters()
    stop.set()
    sim = parent.recv()
    process.join(10)
    return {"sent": sim.get("blocks", 0), "skipped": sim.get("skipped", 0),
            "span": (last - first + 1) if first is not None else 0,
            "delivered": delivered, "dropped": counters.dropped, "torn": torn,
            "resends": counters.resend_requests, "blocks_dropped": counters.blocks_dropped,
            "packets_lost": sim.get("lost", 0), "rate": delivered / elapsed}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rates", type=float, nargs="+", default=[30.0, 45.0])
    parser.add_argument("--loss", type=float, nargs="+", default=[0.0, 0.01])
    args = parser.parse_args()
    print(f"load before: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}; "
          f"{SIZE} x {SIZE} Mono12 ({SIZE * SIZE * 2 / 1e6:.1f} MB/frame), 8192-byte packets, 1 Gbit/s pace")
    print(f"{'rate Hz':>8} {'loss':>6} {'sent':>6} {'unsent':>7} {'delivered':>10} {'lost':>5} {'dropped':>8} "
          f"{'torn':>5} {'gave up':>8} {'resends':>8} {'pkts lost':>9} {'fps':>6}")
    for rate in args.rates:
        for loss in args.loss:
            r = run(rate, loss, args.seconds)
            lost = r["sent"] - r["delivered"]  # sent by the camera, never delivered here (in flight at stop: <= 2)
            print(f"{rate:8.1f} {loss:6.3f} {r['sent']:6d} {r['skipped']:7d} {r['delivered']:10d} {lost:5d} "
                  f"{r['dropped']:8d} {r['torn']:5d} {r['blocks_dropped']:8d} {r['resends']:8d} {r['packets_lost']:9d} "
                  f"{r['rate']:6.1f}")


if __name__ == "__main__":
    main()
