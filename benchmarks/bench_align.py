"""Benchmark of the alignment loop: the sensitivity matrix, and one alignment on the simulated bench.

Run:  .venv/bin/python benchmarks/bench_align.py [--config F.toml] [--repeats 3] [--json]

BLAS pinned to one thread, as the command line does. The default is the packaged simulated bench
(``wavestack/config/tma-alignment.toml``: 128 x 256 camera grid, 5 field points, Noll 2..22, both
PI controllers simulated on loopback). It prints the time to build the sensitivity matrix (central
differences: 11 ray traces and fits per field point; best of ``--repeats``), then for each
iteration of one alignment the wall time from the first field-stage move to the verified
read-back (or to the final check), which includes the field stage's and the hexapod's simulated
travel at their configured velocities.
"""

from __future__ import annotations

import argparse
import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import json  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from contextlib import ExitStack  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.align import TermFitter, build_sensitivity  # noqa: E402
from wavestack.align.loop import AlignmentLoop, IterationRecord  # noqa: E402
from wavestack.align.session import open_session, options_of  # noqa: E402
from wavestack.config.align import load_align_config  # noqa: E402
from wavestack.simulators.tma import TmaModel  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", help="alignment bench TOML (default: the packaged simulated bench)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = load_align_config(args.config)
    model = TmaModel(config.design)
    fitter = TermFitter(model.pupil_mask, config.align.max_noll)
    times = []
    for _ in range(max(1, args.repeats)):
        started = time.perf_counter()
        build_sensitivity(model.wavefront, config.design.field_points_deg, fitter, at=np.zeros(5),
                          steps=np.array(config.align.steps), scales=np.array(config.align.scales))
        times.append(time.perf_counter() - started)
    checks: list[float] = []
    records: list[IterationRecord] = []

    def on_event(phase: str, reason: str) -> None:
        if phase == "checking":
            checks.append(time.perf_counter())

    with ExitStack() as stack:
        session = open_session(config, stack)
        started = time.perf_counter()
        summary = AlignmentLoop(**session.loop_arguments(), options=options_of(config), stop=threading.Event(),
                                on_iteration=records.append, on_event=on_event).run()
    walls = np.diff([started, *checks])
    report = {"sensitivity_s": min(times), "rows": len(config.design.field_points_deg) * fitter.count,
              "iterations": [{"iteration": r.iteration, "worst_rms_waves": max(r.rms_waves), "wall_s": float(w)}
                             for r, w in zip(records, walls)],
              "final_phase": summary.state.phase.value}
    if args.json:
        print(json.dumps(report))
        return
    print(f"sensitivity matrix ({report['rows']} x 5): {report['sensitivity_s'] * 1e3:.0f} ms "
          f"(best of {len(times)})")
    for row in report["iterations"]:
        print(f"iteration {row['iteration']}: worst RMS {row['worst_rms_waves']:.4f} waves, {row['wall_s']:.2f} s")
    print(f"final: {report['final_phase']}")


if __name__ == "__main__":
    main()
