"""Benchmark of the dwell-time solvers on a realistic 512 x 512 surface with a 15-pixel FWHM TIF.

Run:  .venv/bin/python benchmarks/bench_dwell.py [--fft-runs 5] [--lsq-runs 3] [--lsq-step 6] [--bounded-runs 3]

BLAS, FFT workers and OpenCV pinned to one thread. The surface (nm of surface height) is on a
512 x 512 grid of 0.2 mm pixels, clear aperture a disc of radius 230 px (a 26 px margin, more than
the 19 px TIF radius): low-order Zernike terms (power, astigmatism, coma, trefoil, spherical)
plus the bundled Zygo MetroPro map (read with ``wavestack.pipeline.read_measured_map``, its
invalid pixels filled from the nearest valid one, resampled onto the aperture's bounding box),
each scaled to 35 nm RMS, the sum to 50 nm RMS. The TIF is a Gaussian of 15 px (3 mm) FWHM,
5 nm/s peak, cut at 3 sigma.

Prints, per solver, the median wall time over its runs (after one warm-up for the FFT solver;
the least-squares runs are long enough that the first one is counted) and the predicted
residual RMS / PV in the clear aperture and the total dwell, side by side; then the FFT solver
again with the least-squares solution's total dwell as its budget (``max_total_dwell_s``) and no
RMS slack (the least RMS within the budget), to compare the two at equal machine time; then the
bounded solver (``solve_dwell_bounded``: Tikhonov start, projected gradient, no full piston) with
no limits and with the same budget, and the ratios of every solver's RMS, total dwell and time to
the FFT solver's, from the same run. The least-squares
solver dwells on every ``--lsq-step``-th pixel of the dwell grid in both directions: the full
grid (~200,000 points, ~250 million matrix entries) does not fit the solver's matrix budget.
At 6 px (0.94 sigma) the lattice's Nyquist frequency is one the TIF passes at 0.4 % of its DC
gain, beyond what the FFT filter's threshold keeps, so the coarse lattice loses nothing the tool
could correct. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from scipy.ndimage import distance_transform_edt  # noqa: E402

from wavestack.pipeline import read_measured_map, zernike_basis  # noqa: E402
from wavestack.pipeline.polishing import (  # noqa: E402
    DwellSolution,
    ToolInfluence,
    dwell_grid,
    solve_dwell_bounded,
    solve_dwell_fft,
    solve_dwell_lsq,
)

ZYGO = Path("/work/shared/data/zygo-dat/valid_zygo_dat_file.dat")
SIZE, RADIUS_PX, PIXEL_MM = 512, 230.0, 0.2
FWHM_PX, PEAK_NM_S = 15.0, 5.0
LOW_ORDER = {(2, 0): 1.0, (2, 2): 0.8, (2, -2): -0.4, (3, 1): 0.5, (3, -3): 0.3, (4, 0): -0.4}


def surface() -> tuple[np.ndarray, np.ndarray]:
    """The 512 x 512 test surface (nm, NaN outside) and its clear aperture."""
    rows, cols = np.indices((SIZE, SIZE), dtype=np.float64)
    x, y = (cols - (SIZE - 1) / 2) / RADIUS_PX, ((SIZE - 1) / 2 - rows) / RADIUS_PX
    aperture = x**2 + y**2 < 1.0
    basis = zernike_basis(list(LOW_ORDER), x[aperture], y[aperture])
    figure = np.zeros((SIZE, SIZE))
    figure[aperture] = basis @ np.array(list(LOW_ORDER.values()))
    measured = read_measured_map(ZYGO)
    _, (near_r, near_c) = distance_transform_edt(~measured.valid, return_indices=True)
    filled = measured.map_nm[near_r, near_c]
    box = int(2 * RADIUS_PX) + 1
    start = int(round((SIZE - 1) / 2 - RADIUS_PX))
    zygo = np.zeros((SIZE, SIZE))
    zygo[start : start + box, start : start + box] = cv2.resize(filled, (box, box), interpolation=cv2.INTER_AREA)
    total = np.zeros((SIZE, SIZE))
    for part in (figure, zygo):
        inside = part[aperture] - part[aperture].mean()
        total[aperture] += inside * 35.0 / inside.std()
    total[aperture] *= 50.0 / total[aperture].std()
    return np.where(aperture, total, np.nan), aperture


def timed(solve: Callable[[], DwellSolution], runs: int, warm_up: bool) -> tuple[DwellSolution, float]:
    """The last solution and the median wall time (s) of ``runs`` calls."""
    if warm_up:
        solve()
    times, solution = [], None
    for _ in range(runs):
        started = time.perf_counter()
        solution = solve()
        times.append(time.perf_counter() - started)
    assert solution is not None
    return solution, float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fft-runs", type=int, default=5, help="timed FFT solves (default 5)")
    parser.add_argument("--lsq-runs", type=int, default=3, help="timed least-squares solves (default 3)")
    parser.add_argument("--lsq-step", type=int, default=6, help="least-squares dwell point spacing, px (default 6)")
    parser.add_argument("--bounded-runs", type=int, default=3, help="timed bounded solves (default 3)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    height, aperture = surface()
    tif = ToolInfluence.gaussian(fwhm_mm=FWHM_PX * PIXEL_MM, peak_rate_nm_s=PEAK_NM_S, pixel_mm=PIXEL_MM)
    inside = height[aperture]
    print(f"surface {SIZE} x {SIZE}, {aperture.sum()} px in the clear aperture: RMS {inside.std():.2f} nm, "
          f"PV {np.ptp(inside):.1f} nm; TIF FWHM {FWHM_PX:g} px, radius {tif.radius_px} px, peak {PEAK_NM_S:g} nm/s")
    grid = dwell_grid(aperture, tif)
    rows, cols = np.nonzero(grid)
    keep = (rows % args.lsq_step == 0) & (cols % args.lsq_step == 0)
    points = np.c_[rows[keep], cols[keep]]
    fft, fft_s = timed(lambda: solve_dwell_fft(height, aperture, tif), args.fft_runs, warm_up=True)
    lsq, lsq_s = timed(lambda: solve_dwell_lsq(height, aperture, tif, points_px=points), args.lsq_runs, warm_up=False)
    budget = lsq.total_dwell_s
    held, held_s = timed(lambda: solve_dwell_fft(height, aperture, tif, max_total_dwell_s=budget, rms_tolerance=0.0), args.fft_runs, warm_up=True)
    free, free_s = timed(lambda: solve_dwell_bounded(height, aperture, tif), args.bounded_runs, warm_up=False)
    bounded, bounded_s = timed(lambda: solve_dwell_bounded(height, aperture, tif, max_total_dwell_s=budget),
                               args.bounded_runs, warm_up=False)
    print(f"{'solver':<38}{'time (median)':>16}{'RMS nm':>10}{'PV nm':>10}{'total dwell s':>16}"
          f"{'RMS / fft':>11}{'dwell / fft':>13}{'time / fft':>12}")
    for name, solution, seconds, runs in (
        (f"fft (RIFTA-style, {grid.sum()} px grid)", fft, fft_s, args.fft_runs),
        (f"lsq (every {args.lsq_step} px: {points.shape[0]} points)", lsq, lsq_s, args.lsq_runs),
        ("fft, budget = lsq's dwell, no slack", held, held_s, args.fft_runs),
        ("bounded (Tikhonov + FISTA), no limits", free, free_s, args.bounded_runs),
        ("bounded, budget = lsq's dwell", bounded, bounded_s, args.bounded_runs),
    ):
        print(f"{name:<38}{seconds:>9.2f} s (N={runs}){solution.rms_nm:>10.3f}{solution.pv_nm:>10.2f}"
              f"{solution.total_dwell_s:>16.0f}{solution.rms_nm / fft.rms_nm:>11.3f}"
              f"{solution.total_dwell_s / fft.total_dwell_s:>13.3f}{seconds / fft_s:>12.1f}")
    print(f"fft: threshold {fft.diagnostics['threshold']:.3g}, iterations {fft.diagnostics['iterations_run']}, "
          f"piston dwell {fft.diagnostics['piston_dwell_s']:.3g} s/px; lsq: {lsq.diagnostics['nonzeros']} matrix "
          f"entries, {lsq.diagnostics['iterations']} trust-region iterations ({lsq.diagnostics['message']}); bounded: "
          f"start lambda {bounded.diagnostics['damping']:.3g}, {bounded.diagnostics['iterations_run']} iterations "
          f"({bounded.diagnostics['stopped']})")


if __name__ == "__main__":
    main()
