"""Benchmark of the precomputed fitter: per-frame refit against memory bandwidth and lstsq.

Run:  .venv/bin/python benchmarks/bench_fit.py [--repeats 30] [--threads 1]

Input: a 1024 x 1024 frame whose aperture is a centred disk of radius 448 px (630,404 valid
pixels), holding a random 36-term Zernike wavefront plus noise. For 36 and 231 Noll modes in
float32 and float64 it prints the medians over ``--repeats`` runs of

* refit: ``fitter.fit(frame)`` (gather, one operator pass, small solve);
* memory pass: one numpy read pass over the bytes a refit must read (operator + frame),
  measured in the same run, so the ratio is free of machine-to-machine differences;
* lstsq: ``numpy.linalg.lstsq`` of the same design matrix against the same samples (what a
  refit costs without a precomputed factorisation; fewer repeats, it is slow);
* build: mask to ready fitter (aperture, basis, Gram, factorisation).

BLAS threads are pinned through the environment before numpy is imported (default 1).
"""

from __future__ import annotations

import argparse
import os
import sys


def _parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30, help="runs per refit median (30)")
    parser.add_argument("--lstsq-repeats", type=int, default=3, help="runs per lstsq median (3)")
    parser.add_argument("--build-repeats", type=int, default=5, help="runs per build median (5)")
    parser.add_argument("--threads", type=int, default=1, help="BLAS threads (1)")
    parser.add_argument("--modes", type=int, nargs="+", default=[36, 231])
    return parser.parse_args()


ARGS = _parse()
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = str(ARGS.threads)

import time  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.pipeline import build_fitter, mode_list, zernike_basis  # noqa: E402

SIZE, RADIUS = 1024, 448.0


def median_seconds(action, repeats: int) -> float:
    """Median wall time of ``action()`` over ``repeats`` runs, after one warm-up run."""
    action()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        action()
        times.append(time.perf_counter() - started)
    return float(np.median(times))


def make_frame() -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.indices((SIZE, SIZE))
    mask = np.hypot(rows - 511.5, cols - 511.5) <= RADIUS
    r, c = np.nonzero(mask)
    x, y = (c - 511.5) / RADIUS, (511.5 - r) / RADIUS
    rng = np.random.default_rng(0)
    frame = np.full((SIZE, SIZE), np.nan)
    values = zernike_basis(mode_list("noll", 36), x, y) @ rng.normal(0, 0.02, 36)
    frame[r, c] = values + rng.normal(0, 0.001, values.size)
    return mask, frame


def main() -> int:
    mask, frame64 = make_frame()
    print(f"# bench_fit: {SIZE}x{SIZE} frame, {int(mask.sum())} valid pixels, "
          f"BLAS threads {ARGS.threads}, medians of {ARGS.repeats} refits / "
          f"{ARGS.lstsq_repeats} lstsq / {ARGS.build_repeats} builds")
    build = median_seconds(lambda: build_fitter(mask, modes=36), ARGS.build_repeats)
    print(f"build (mask -> ready fitter, 36 modes, float32): {build:.3f} s  (target <= 3 s)")
    print()
    print("| modes | dtype | refit ms | memory pass ms | refit / pass | lstsq ms | lstsq / refit |")
    print("|---:|---|---:|---:|---:|---:|---:|")
    for modes in ARGS.modes:
        for dtype in (np.float32, np.float64):
            fitter = build_fitter(mask, modes=modes, dtype=dtype)
            frame = frame64.astype(dtype)
            refit = median_seconds(lambda: fitter.fit(frame), ARGS.repeats)
            operator = fitter.operator  # the bytes a refit reads, besides the frame
            memory = median_seconds(lambda: (operator.sum(), frame.sum()), ARGS.repeats)
            rows, cols = np.nonzero(mask)
            design = fitter.operator
            samples = frame[rows, cols]
            lstsq = median_seconds(
                lambda: np.linalg.lstsq(design, samples, rcond=None), ARGS.lstsq_repeats
            )
            print(f"| {modes} | {np.dtype(dtype).name} | {refit * 1e3:.2f} | {memory * 1e3:.2f} | "
                  f"{refit / memory:.2f} | {lstsq * 1e3:.0f} | {lstsq / refit:.0f} |")
            del fitter, design
    return 0


if __name__ == "__main__":
    sys.exit(main())
