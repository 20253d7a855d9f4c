"""Benchmark of the refit: the moment path and the operator path against reading the frame once.

Run:  .venv/bin/python benchmarks/bench_fit.py [--sizes 1024 2048] [--modes 36 231] [--repeats 15]

Input: a square float32 frame whose aperture is a centred disk of radius 0.4375 x size (630,404
valid pixels at 1024 x 1024, 2,521,764 at 2048 x 2048), holding a random Zernike wavefront plus
noise. For each size and mode count it prints the medians over ``--repeats`` interleaved rounds
(one of each timing per round, so load on the machine hits them alike) of

* floor: one numpy sum over the frame, the least a refit must do (read every sample once);
* sgemm: one float32 product of the frame's bounding box (a strided view, no copy) with its
  column Legendre table, D + 1 wide: the BLAS product alone, without copy, masking or squares
  (a reference for the floor: what one pass of sgemm over the frame costs against np.sum);
* moments: ``fitter.fit(frame)`` of the default fitter (separable Legendre moments, no operator;
  the ``pass`` column says whether the float32 or the float64 pass served the float32 frame);
* operator: ``fitter.fit(frame)`` of the same basis built with ``refit="operator"``;
* lstsq: ``numpy.linalg.lstsq`` of the samples against the basis (no precomputation; few runs);

and the build times of both fitters. Where an operator (or lstsq's design matrix) would not fit
the memory budget the row says so instead of a figure. Last, a child process builds and runs a
231-mode moment fitter at the largest size and reports its peak memory above its own baseline
(the kernel's resident high-water mark, reset just before the build, and tracemalloc's count).

BLAS threads are pinned through the environment before numpy is imported (default 1).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys


def _parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048])
    parser.add_argument("--modes", type=int, nargs="+", default=[36, 231])
    parser.add_argument("--repeats", type=int, default=15, help="interleaved rounds per median (15)")
    parser.add_argument("--lstsq-repeats", type=int, default=1, help="lstsq runs per median (1)")
    parser.add_argument("--max-operator-gb", type=float, default=1.0,
                        help="skip the operator path and lstsq where the float64 design exceeds this (1 GB)")
    parser.add_argument("--threads", type=int, default=1, help="BLAS threads (1)")
    parser.add_argument("--annulus", type=float, default=0.35,
                        help="obscuration of the annulus method's rows, at the smallest size (0.35; 0 skips them)")
    parser.add_argument("--memory-child", type=int, nargs=2, metavar=("SIZE", "MODES"), help=argparse.SUPPRESS)
    return parser.parse_args()


ARGS = _parse()
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = str(ARGS.threads)

import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.pipeline import build_fitter, mode_list, zernike_basis  # noqa: E402
from wavestack.pipeline.fit.legendre_moments import legendre_table  # noqa: E402


def make_frame(size: int, modes: int = 36) -> tuple[np.ndarray, np.ndarray]:
    """A disk mask and a float32 frame (NaN outside) of a random wavefront plus noise.

    Made in blocks of rows, so that the process's baseline stays near the frame's own size.
    """
    centre, radius = (size - 1) / 2.0, 0.4375 * size
    cols = np.arange(size)
    rng = np.random.default_rng(0)
    truth = rng.normal(0, 0.02, modes)
    mask = np.zeros((size, size), dtype=bool)
    frame = np.full((size, size), np.nan, dtype=np.float32)
    for start in range(0, size, 128):
        rows = np.arange(start, min(start + 128, size))[:, None]
        mask[rows[:, 0]] = np.hypot(rows - centre, cols[None, :] - centre) <= radius
        r, c = np.nonzero(mask[start:start + 128])
        values = zernike_basis(mode_list("noll", modes), (c - centre) / radius, (centre - r - start) / radius) @ truth
        frame[r + start, c] = values + rng.normal(0, 0.001, values.size)
    return mask, frame


def timed(action) -> float:
    started = time.perf_counter()
    action()
    return time.perf_counter() - started


def interleaved(actions: dict[str, object], repeats: int) -> dict[str, float]:
    """Median seconds of each action over ``repeats`` rounds that run every action once."""
    for action in actions.values():
        action()  # warm-up
    times: dict[str, list[float]] = {name: [] for name in actions}
    for _ in range(repeats):
        for name, action in actions.items():
            times[name].append(timed(action))
    return {name: float(np.median(values)) for name, values in times.items()}


def bench_size(size: int) -> None:
    mask, frame = make_frame(size)
    n = int(mask.sum())
    print(f"\n## {size} x {size}: {n} valid pixels, float32 frame ({frame.nbytes / 1e6:.1f} MB)\n")
    print("| modes | floor ms | sgemm ms | moments ms | operator ms | lstsq ms | sgemm / floor | moments / floor | "
          "operator / moments | lstsq / moments | build moments s | build operator s | strips | pass |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    box = frame[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    for modes in ARGS.modes:
        tick = time.perf_counter()
        moments = build_fitter(mask, modes=modes, dtype=np.float32)
        build_moments = time.perf_counter() - tick
        assert moments.refit == "moments", moments.diagnostics
        operator = None
        design_gb = 8 * n * modes / 1e9
        degree = max(n for n, _ in mode_list("noll", modes))
        table = legendre_table(int(cols[0]), int(cols[-1]) + 1, degree).astype(np.float32)
        actions = {"floor": lambda: frame.sum(), "sgemm": lambda: box @ table, "moments": lambda: moments.fit(frame)}
        # The projection is private to the fitter; the benchmark reports which pass ran.
        single = moments._projection.float32_frame_pass

        build_operator = lstsq = float("nan")
        if design_gb <= ARGS.max_operator_gb:
            tick = time.perf_counter()
            operator = build_fitter(mask, modes=modes, dtype=np.float32, refit="operator")
            build_operator = time.perf_counter() - tick
            actions["operator"] = lambda: operator.fit(frame)
        times = interleaved(actions, ARGS.repeats)
        if operator is not None:
            design = operator.operator[:, :modes]
            samples = frame[mask]
            lstsq = float(np.median([timed(lambda: np.linalg.lstsq(design, samples, rcond=None))
                                     for _ in range(ARGS.lstsq_repeats)]))
            check = np.abs(moments.fit(frame).coefficients - operator.fit(frame).coefficients).max()
            assert check < 1e-5, f"moments and operator differ by {check}"
            del design
        floor, fit, sgemm = times["floor"], times["moments"], times["sgemm"]
        op = times.get("operator", float("nan"))
        skipped = f"(design {design_gb:.1f} GB > {ARGS.max_operator_gb} GB)"
        cells = [f"{op * 1e3:.2f}" if operator else skipped, f"{lstsq * 1e3:.0f}" if operator else skipped]
        print(f"| {modes} | {floor * 1e3:.3f} | {sgemm * 1e3:.3f} | {fit * 1e3:.2f} | {cells[0]} | {cells[1]} | "
              f"{sgemm / floor:.1f} | {fit / floor:.1f} | {op / fit:.1f} | {lstsq / fit:.0f} | {build_moments:.2f} | "
              f"{build_operator:.2f} | {moments.diagnostics.moment_strips} | {single} |")
        del moments, operator


def bench_annulus(size: int, obscuration: float) -> None:
    """The ``annulus`` method on the disk of :func:`make_frame` less a central hole: moments vs operator."""
    mask, frame = make_frame(size)
    rows, cols = np.indices(mask.shape, dtype=np.float32)
    mask &= np.hypot(rows - (size - 1) / 2.0, cols - (size - 1) / 2.0) >= obscuration * 0.4375 * size
    del rows, cols
    frame = np.where(mask, frame, np.float32(np.nan))
    print(f"\n## annulus method, {size} x {size}, obscuration {obscuration}: {int(mask.sum())} valid pixels\n")
    print("| modes | floor ms | moments ms | operator ms | moments / floor | operator / moments | boxes |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for modes in ARGS.modes:
        moments = build_fitter(mask, method="annulus", modes=modes, dtype=np.float32)
        actions = {"floor": lambda: frame.sum(), "moments": lambda: moments.fit(frame)}
        if 8 * int(mask.sum()) * modes / 1e9 <= ARGS.max_operator_gb:
            operator = build_fitter(mask, method="annulus", modes=modes, dtype=np.float32, refit="operator")
            actions["operator"] = lambda: operator.fit(frame)
        times = interleaved(actions, ARGS.repeats)
        op = times.get("operator", float("nan"))
        print(f"| {modes} | {times['floor'] * 1e3:.3f} | {times['moments'] * 1e3:.2f} | {op * 1e3:.2f} | "
              f"{times['moments'] / times['floor']:.1f} | {op / times['moments']:.1f} | "
              f"{moments.diagnostics.moment_strips} ({moments.refit}) |")


def _resident_mib(field: str) -> float:
    """``VmRSS`` (now) or ``VmHWM`` (peak since the last reset) of this process, MiB (Linux)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"/proc/self/status has no {field}")


def memory_child(size: int, modes: int) -> None:
    """Build and fit once; print the peak resident memory above the baseline (frame and mask made).

    The peak is the kernel's high-water mark ``VmHWM``, reset to the current RSS just before the
    build (``/proc/self/clear_refs``), so earlier peaks (imports, making the frame) do not count;
    a warm-up build on a small frame first does the lazy imports and BLAS buffers.
    """
    small_mask, small_frame = make_frame(256)
    build_fitter(small_mask, modes=modes, dtype=np.float32).fit(small_frame, residual=True)
    mask, frame = make_frame(size)
    baseline = _resident_mib("VmRSS")
    with open("/proc/self/clear_refs", "w") as clear:
        clear.write("5")  # reset VmHWM to the current RSS
    tracemalloc.start()
    fitter = build_fitter(mask, modes=modes, dtype=np.float32)
    fitter.fit(frame)
    build_and_fit = _resident_mib("VmHWM") - baseline
    _, traced = tracemalloc.get_traced_memory()
    fitter.fit(frame, residual=True)
    with_residual = _resident_mib("VmHWM") - baseline
    tracemalloc.stop()
    print(f"peak memory above baseline, {modes} modes at {size} x {size} ({fitter.refit}): build + fit "
          f"{build_and_fit:.1f} MiB RSS (tracemalloc {traced / 2**20:.1f} MiB); with a fit(residual=True) "
          f"{with_residual:.1f} MiB (target: build and fit < 100 MB)")


def main() -> int:
    if ARGS.memory_child:
        memory_child(*ARGS.memory_child)
        return 0
    load = os.getloadavg()
    print(f"# bench_fit: BLAS threads {ARGS.threads}, medians of {ARGS.repeats} interleaved rounds "
          f"({ARGS.lstsq_repeats} lstsq), load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}")
    for size in ARGS.sizes:
        bench_size(size)
    if ARGS.annulus > 0:
        bench_annulus(min(ARGS.sizes), ARGS.annulus)
    print()
    child = [sys.executable, __file__, "--threads", str(ARGS.threads), "--memory-child", str(max(ARGS.sizes)), "231"]
    sys.stdout.flush()
    return subprocess.run(child, check=False).returncode


if __name__ == "__main__":
    sys.exit(main())
