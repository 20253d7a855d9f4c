"""Benchmark of the simulated TMA (batoid): one wavefront, and a finite-difference sensitivity matrix.

Run:  .venv/bin/python benchmarks/bench_tma.py [--config wavestack/config/tma-alignment.toml] [--repeats 30]

BLAS pinned to one thread. Prints the median and 99th percentile over ``--repeats`` of

* one wavefront at the configured camera grid and at 256 x 256 (a new pose each time, so no
  cached optic is reused; the per-field reference point is cached after the first call);
* the full central-difference sensitivity matrix: X Y Z U V of the aligned mirror, 3 field
  points, +/- one step each (30 wavefronts) and a Noll 2..11 fit of each difference with
  wavestack's circle basis on the circle through the pupil's corners;

and the condition number of that matrix (columns normalised), with and without the tilt terms.
Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import dataclasses  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.config.tma import load_tma_config  # noqa: E402
from wavestack.pipeline.zernike import noll_to_nm, zernike_basis  # noqa: E402
from wavestack.pipeline.telescope import HexapodPose, TmaDesign, TmaModel  # noqa: E402

STEPS = {"x": 0.02, "y": 0.02, "z": 0.02, "u": 0.002, "v": 0.002}  # mm, deg
FIELDS = ((0.0, -0.6), (-0.5, -0.8), (0.5, -0.4))


def timed(action: Callable[[int], object], repeats: int) -> tuple[float, float]:
    """Median and 99th percentile wall time of ``action(i)`` in seconds, after one warm-up."""
    action(0)
    times = []
    for index in range(repeats):
        started = time.perf_counter()
        action(index + 1)
        times.append(time.perf_counter() - started)
    return float(np.median(times)), float(np.percentile(times, 99))


def report(name: str, result: tuple[float, float], repeats: int) -> None:
    median, p99 = result
    print(f"{name:<52} median {median * 1e3:8.2f} ms   p99 {p99 * 1e3:8.2f} ms   ({repeats} runs)")


def noll_fitter(design: TmaDesign, model: TmaModel) -> Callable[[np.ndarray], np.ndarray]:
    """A least-squares Noll 2..11 fit on the model's pupil (basis factorised once)."""
    rows, cols = design.camera_shape
    x = (np.arange(cols) - (cols - 1) / 2) * design.pixel_mm
    y = ((rows - 1) / 2 - np.arange(rows)) * design.pixel_mm
    xx, yy = np.meshgrid(x, y)
    mask = model.pupil_mask
    radius = float(np.hypot(*design.pupil.size_mm) / 2)
    basis = zernike_basis([noll_to_nm(j) for j in range(1, 12)], xx[mask] / radius, yy[mask] / radius)
    pinv = np.linalg.pinv(basis)
    return lambda w: (pinv @ w[mask])[1:]


def sensitivity(model: TmaModel, fit: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    columns = []
    for dof, step in STEPS.items():
        plus, minus = HexapodPose(**{dof: step}), HexapodPose(**{dof: -step})
        columns.append(np.concatenate([fit(model.wavefront(f, plus) - model.wavefront(f, minus)) / (2 * step)
                                       for f in FIELDS]))
    return np.column_stack(columns)


def condition(matrix: np.ndarray) -> float:
    s = np.linalg.svd(matrix / np.linalg.norm(matrix, axis=0), compute_uv=False)
    return float(s[0] / s[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="wavestack/config/tma-alignment.toml", help="TOML file with [tma]")
    parser.add_argument("--repeats", type=int, default=30, help="timed runs per case (default 30)")
    args = parser.parse_args()
    design, errors = load_tma_config(args.config)
    square = dataclasses.replace(design, camera_shape=(256, 256), pixel_mm=max(design.pupil.size_mm) / 250)
    for label, d in ((f"{design.camera_shape[0]} x {design.camera_shape[1]}", design), ("256 x 256", square)):
        model = TmaModel(d, errors)
        pixels = int(model.pupil_mask.sum())
        report(f"one wavefront, {label} grid ({pixels} pupil pixels)",
               timed(lambda i: model.wavefront(d.field_points_deg[0], HexapodPose(z=1e-4 * i)), args.repeats),
               args.repeats)
    model = TmaModel(design, errors)
    fit = noll_fitter(design, model)
    repeats = max(1, args.repeats // 10)
    report("sensitivity matrix, 5 dof x 3 fields (30 wavefronts)",
           timed(lambda i: sensitivity(TmaModel(design, errors), fit), repeats), repeats)
    matrix = sensitivity(model, fit)
    without_tilt = np.concatenate([matrix[k * 10 + 2:(k + 1) * 10] for k in range(len(FIELDS))])
    print(f"condition number (columns normalised): Noll 2-11 {condition(matrix):.1f}, "
          f"Noll 4-11 {condition(without_tilt):.1f}")


if __name__ == "__main__":
    main()
