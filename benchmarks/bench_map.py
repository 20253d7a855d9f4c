"""Benchmark of the CSF-QCM map and of building a mapped fitter.

Run:  .venv/bin/python benchmarks/bench_map.py [--repeats 5]

With BLAS pinned to one thread (set here before numpy loads), it prints the medians over
``--repeats`` runs of:

* the CSF-QCM map of each paper aperture at 512 x 512 with a ~15k-vertex mesh, per stage
  (mesh, curve-shortening flow, factorisation, harmonic solves and modulus, total);
* mask to ready ``csf-qcm`` fitter (36 modes, float32) for a 1024 x 1024 frame: a disk of radius
  448 px (630,548 pixels) and the eccentric annulus scaled to 1024 px.
"""

from __future__ import annotations

import argparse
import os
import sys

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import time  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.bench import PAPER_APERTURES, annulus_circular_hole_mask  # noqa: E402
from wavestack.pipeline import Aperture, build_fitter  # noqa: E402
from wavestack.pipeline import csf_qcm_map  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"# bench_map: BLAS threads 1, medians of {args.repeats} runs, seconds")
    print()
    print("| aperture (512 px) | vertices | mesh | csf | factorise | map | total |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, make in PAPER_APERTURES.items():
        aperture = Aperture.from_mask(make(512))
        runs = []
        for _ in range(args.repeats):
            started = time.perf_counter()
            mapping = csf_qcm_map(aperture)
            runs.append({**mapping.timings, "total": time.perf_counter() - started})
        median = {key: float(np.median([run[key] for run in runs])) for key in runs[0]}
        print(f"| {name} | {mapping.mesh.n_vertices} | {median['mesh']:.3f} | {median['csf']:.3f} | "
              f"{median['factorise']:.3f} | {median['map']:.3f} | {median['total']:.3f} |")
    print()
    rows, cols = np.indices((1024, 1024))
    masks = {
        "disk r = 448 px": np.hypot(rows - 511.5, cols - 511.5) <= 448,
        "eccentric annulus": annulus_circular_hole_mask(1024),
    }
    print("| 1024 x 1024 mask | pixels | mask -> ready csf-qcm fitter (36 modes, float32) |")
    print("|---|---:|---:|")
    for name, mask in masks.items():
        times = []
        for _ in range(args.repeats):
            started = time.perf_counter()
            build_fitter(mask, method="csf-qcm", modes=36)
            times.append(time.perf_counter() - started)
        print(f"| {name} | {int(mask.sum())} | {np.median(times):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
