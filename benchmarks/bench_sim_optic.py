"""Benchmark of the simulated test optic: render time of interferograms and Shack-Hartmann frames.

Run:  .venv/bin/python benchmarks/bench_sim_optic.py [--repeats 50]

BLAS and OpenCV pinned to one thread. Prints the median and 99th percentile over ``--repeats``
renders (after one warm-up) of

* 1024 x 1024 interferograms, 12 bits, 11 Noll terms on a disk of radius 400 px, noise on:
  a static optic, and one with drift, carrier fringes and vibration (the extra per-frame pass);
* 1280 x 1024 Shack-Hartmann spot frames, 16 bits, 25 px lenslets (40 x 45), noise on.

Each time includes the returned ground truth. The one-off set-up (basis products, noise pool,
subaperture operators) is printed separately. Nothing is asserted: the target is <= 20 ms per
interferogram on the project machine.
"""

from __future__ import annotations

import argparse
import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from wavestack.simulators.optic import ApertureShape, OpticSettings, TestOptic  # noqa: E402
from wavestack.simulators.spots import LensletArraySettings, SpotRenderer  # noqa: E402


def timed(action: Callable[[int], object], repeats: int) -> tuple[float, float]:
    """Median and 99th percentile wall time of ``action(i)`` in seconds, after one warm-up."""
    action(0)
    times = []
    for index in range(repeats):
        started = time.perf_counter()
        action(index)
        times.append(time.perf_counter() - started)
    return float(np.median(times)), float(np.percentile(times, 99))


def setup_time(build: Callable[[], object]) -> tuple[object, float]:
    started = time.perf_counter()
    built = build()
    return built, time.perf_counter() - started


def report(name: str, result: tuple[float, float], repeats: int) -> None:
    median, p99 = result
    print(f"{name:<58} median {median * 1e3:7.2f} ms   p99 {p99 * 1e3:7.2f} ms   ({repeats} runs)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=50, help="timed renders per case (default 50)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    repeats = args.repeats

    static = OpticSettings(aperture=ApertureShape(centre_px=(512.0, 512.0), radius_px=400.0))
    optic, seconds = setup_time(lambda: TestOptic(static, 1024, 1024))
    print(f"set-up of a 1024 x 1024 optic (11 terms): {seconds * 1e3:.0f} ms")
    report("interferogram 1024 x 1024, static optic",
           timed(lambda i: optic.interferogram(0.01 * i, (i % 4) * np.pi / 2), repeats), repeats)

    moving = OpticSettings(
        aperture=ApertureShape(centre_px=(512.0, 512.0), radius_px=400.0),
        drift_waves_per_s=(0.0, 0.01, 0.0, 0.02) + (0.0,) * 7,
        carrier_cycles=(80.0, 20.0), vibration_rms_rad=0.2, vibration_hz=35.0,
    )
    drifting = TestOptic(moving, 1024, 1024)
    report("interferogram 1024 x 1024, drift + carrier + vibration",
           timed(lambda i: drifting.interferogram(0.01 * i), repeats), repeats)

    pupil = OpticSettings(aperture=ApertureShape(centre_px=(640.0, 512.0), radius_px=490.0))
    lenslets = LensletArraySettings(offset_px=(140.0, 12.0), bit_depth=16)
    renderer, seconds = setup_time(lambda: SpotRenderer(TestOptic(pupil, 1024, 1280), lenslets, 1024, 1280))
    _, first = setup_time(lambda: renderer.spot_frame(0.0))
    print(f"set-up of a 1280 x 1024 spot renderer: {seconds * 1e3:.0f} ms, first frame "
          f"(subaperture operators) {first * 1e3:.0f} ms")
    rows, cols = renderer.grid_shape
    report(f"spot frame 1280 x 1024, {rows} x {cols} lenslets",
           timed(lambda i: renderer.spot_frame(0.01 * i), repeats), repeats)


if __name__ == "__main__":
    main()
