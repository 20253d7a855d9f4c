"""Benchmark of the alignment loop: the sensitivity matrix, and seeded alignments on the simulated bench.

Run:  .venv/bin/python benchmarks/bench_align.py [--config F.toml] [--repeats 3] [--trials 20]
      [--first 0] [--json]

BLAS pinned to one thread, as the command line does. The default is the packaged simulated bench
(``wavestack/config/tma-alignment.toml``: 128 x 256 camera grid, 5 field points, Noll 2..22 on the
CSF-QCM map, measured through the station's simulated camera with the reference's tilt taken out,
both PI controllers simulated on loopback). It prints the time to build the sensitivity matrix
(central differences: 11 ray traces and fits per field point; best of ``--repeats``), then one
row per seeded trial (seeds ``first .. first + trials - 1``; the mount drawn from
``[align.simulator]``'s ranges, the as-built errors from seed ``1000 + seed``): how it ended, the
corrections, the worst RMS at the start and at the end, and the wall time per iteration (first
field-stage move to the next check, field-stage and hexapod travel included), then the count at
lambda/14 within 5 corrections. ``--trials`` splits over several runs with ``--first``.
"""

from __future__ import annotations

import argparse
import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from align_trials import camera_trial  # noqa: E402
from wavestack.align import TermFitter  # noqa: E402
from wavestack.align.station_source import fixed_aperture  # noqa: E402
from wavestack.config.align import load_align_config  # noqa: E402
from wavestack.pipeline.telescope import TmaModel, build_sensitivity  # noqa: E402


def _sensitivity_time(config, repeats: int) -> tuple[float, int]:  # noqa: ANN001
    model = TmaModel(config.design)
    fitter = TermFitter(fixed_aperture(model.pupil_mask, config.align.edge_px), config.align.max_noll,
                        method=config.align.fit_method)
    times = []
    for _ in range(max(1, repeats)):
        started = time.perf_counter()
        build_sensitivity(model.wavefront, config.design.field_points_deg, fitter, at=np.zeros(5),
                          steps=np.array(config.align.steps), scales=np.array(config.align.scales))
        times.append(time.perf_counter() - started)
    return min(times), len(config.design.field_points_deg) * fitter.count


def _trial(config, seed: int) -> dict[str, object]:  # noqa: ANN001
    checks: list[float] = []

    def on_event(phase: str, reason: str) -> None:
        if phase == "checking":
            checks.append(time.perf_counter())

    started = time.perf_counter()
    summary, moves, _ = camera_trial(config, seed, on_event=on_event)
    first_move = checks[0] if checks else started
    walls = np.diff(checks) if len(checks) > 1 else np.array([])
    worst = [max(r.rms_waves) for r in summary.iterations]
    return {"seed": seed, "phase": summary.state.phase.value, "corrections": summary.state.iterations_done,
            "start_rms_waves": worst[0] if worst else None, "final_rms_waves": worst[-1] if worst else None,
            "iteration_s": [float(w) for w in walls], "trial_s": time.perf_counter() - started,
            "first_check_s": first_move - started, "moves": len(moves)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", help="alignment bench TOML (default: the packaged simulated bench)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = load_align_config(args.config)
    sensitivity_s, rows = _sensitivity_time(config, args.repeats)
    if not args.json:
        print(f"sensitivity matrix ({rows} x 5, {config.align.fit_method}): {sensitivity_s * 1e3:.0f} ms "
              f"(best of {max(1, args.repeats)})")
        print("seed phase          corr  start RMS  final RMS  s/iteration (each)")
    trials = []
    for seed in range(args.first, args.first + args.trials):
        row = _trial(config, seed)
        trials.append(row)
        if not args.json:
            each = " ".join(f"{w:.1f}" for w in row["iteration_s"])  # type: ignore[union-attr]
            print(f"{seed:4d} {row['phase']:<14} {row['corrections']:4d} {row['start_rms_waves']:10.3f} "
                  f"{row['final_rms_waves']:10.4f}  {each}", flush=True)
    target = config.align.target_rms_waves
    met = sum(1 for t in trials if t["phase"] == "target-met" and t["corrections"] <= 5  # type: ignore[operator]
              and t["final_rms_waves"] <= target)  # type: ignore[operator]
    walls = [w for t in trials for w in t["iteration_s"]]  # type: ignore[attr-defined]
    report = {"sensitivity_s": sensitivity_s, "rows": rows, "trials": trials, "met": met,
              "median_iteration_s": float(np.median(walls)) if walls else None}
    if args.json:
        print(json.dumps(report))
        return
    print(f"{met}/{len(trials)} at <= {target:.4f} waves within 5 corrections; median iteration "
          f"{report['median_iteration_s']:.2f} s over {len(walls)} iterations")


if __name__ == "__main__":
    main()
