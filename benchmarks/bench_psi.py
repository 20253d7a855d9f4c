"""Benchmark of the fixed-step PSI formulas at 1024 x 1024, against one memory pass of the input.

Run:  .venv/bin/python benchmarks/bench_psi.py [--rounds 60]

Single thread (BLAS, OpenCV). Same synthetic scene as ``bench_signal.py`` (uint8 frames). The
cases run interleaved, round after round, so that a busy machine slows them alike; each line
gives the minimum and the median in ms and the median's ratio to the median of the memory pass
(``np.sum`` over the frames, as in ``bench_signal.py``). Also printed: the parts of the fast
path (the float32 maps alone, the private copy of the frames kept for ``background``), the
first access to ``background`` (lazy), the float64 path on the same frames as float64, the
bytes read and written, and the phase error of the fast path against the float64 formula.
"""

from __future__ import annotations

import argparse
import os
import sys

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from wavestack.pipeline import four_step, hariharan_five_step  # noqa: E402

SIZE = 1024


def frames_for(steps: np.ndarray) -> np.ndarray:
    """uint8 fringes over a disk of radius 448 px, as in ``bench_signal.py``."""
    rows, cols = np.indices((SIZE, SIZE), dtype=np.float64)
    x, y = (cols - 511.5) / 448, (511.5 - rows) / 448
    mask = x * x + y * y <= 1.0
    phase = np.where(mask, 12.0 * (x * x + y * y) + 3.0 * x**3 + 2.0 * y, 0.0)
    stack = np.where(mask, 120.0, 15.0) + np.where(mask, 90.0, 5.0) * np.cos(phase[None] + steps[:, None, None])
    return np.clip(stack, 0, 255).astype(np.uint8)


def interleaved(cases: dict[str, Callable[[], object]], rounds: int) -> dict[str, np.ndarray]:
    """Wall times in ms of every case, one call of each per round, after one warm-up call."""
    for action in cases.values():
        action()
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(rounds):
        for name, action in cases.items():
            started = time.perf_counter()
            action()
            times[name].append((time.perf_counter() - started) * 1e3)
    return {name: np.asarray(values) for name, values in times.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=60)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    print(f"# bench_psi: {SIZE}x{SIZE} uint8, 1 thread, {args.rounds} interleaved rounds, ms")
    for name, function, count in (("4-step", four_step, 4), ("5-step Hariharan", hariharan_five_step, 5)):
        frames = frames_for(np.arange(count) * np.pi / 2)
        wide = frames.astype(np.float64)

        def lazy_background(function=function, frames=frames) -> None:
            function(frames).background

        cases = {
            "memory pass (np.sum)": lambda frames=frames: np.sum(frames),
            f"{name} (fast path, default call)": lambda function=function, frames=frames: function(frames),
            "  frames as a list (no private copy)": lambda function=function, frames=list(frames): function(frames),
            "  private copy of the frames alone": lambda frames=frames: frames.copy(),
            "  + first access to background": lazy_background,
            f"{name} on float64 frames (float64 path)": lambda function=function, wide=wide: function(wide),
        }
        times = interleaved(cases, args.rounds)
        memory = float(np.median(times["memory pass (np.sum)"]))
        print()
        print("| case | min | median | median / pass |")
        print("|---|---:|---:|---:|")
        for case, values in times.items():
            print(f"| {case} | {values.min():.2f} | {np.median(values):.2f} | {np.median(values) / memory:.1f} |")
        fast, exact = function(frames), function(wide)
        error = np.abs(np.angle(np.exp(1j * (fast.phase.astype(np.float64) - exact.phase))))
        written = fast.phase.nbytes + fast.modulation.nbytes
        print(f"bytes: read {frames.nbytes / 2**20:.0f} MiB, write {written / 2**20:.0f} MiB (float32 phase "
              f"+ modulation) + {frames.nbytes / 2**20:.0f} MiB private copy; float64 maps would write "
              f"{2 * written / 2**20:.0f} MiB")
        print(f"phase error of the fast path against float64: max {error.max():.2e} rad, "
              f"rms {np.sqrt(np.mean(error**2)):.2e} rad")
    return 0


if __name__ == "__main__":
    sys.exit(main())
