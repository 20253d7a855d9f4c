"""Benchmark of the closed polishing loop: one campaign on a simulated polishing station, run by run.

Run:  .venv/bin/python benchmarks/bench_polish.py [--config F.toml] [--max-runs 4] [--solver fft|lsq|bounded]
      [--target-rms-nm 5] [--json]

BLAS pinned to one thread, as the command line does. The default is the packaged simulated station
(``wavestack/config/polishing.toml``: 512 x 512 camera, a 100 mm optic at 0.25 mm per pixel, a 4 mm
FWHM Gaussian tool, the machine's tool 3 % wider and 3 % weaker than the host's model, 2 % per-point
efficiency spread). For each run it prints the surface RMS before, predicted and measured after (nm),
the convergence ratio, the total dwell (simulated s), the solve time (solver and program planning)
and the wall time of the run from its hand-off to the measurement after (the machine's run at its
configured time scale plus the averaged measurement).
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

from wavestack.config.polishing import load_polishing_config  # noqa: E402
from wavestack.polish.loop import LoopOptions, PolishingLoop  # noqa: E402
from wavestack.polish.run_record import RunRecord  # noqa: E402
from wavestack.polish.session import open_session  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", help="polishing station TOML (default: the packaged simulated station)")
    parser.add_argument("--max-runs", type=int, default=4)
    parser.add_argument("--solver", choices=("fft", "lsq", "bounded"))
    parser.add_argument("--target-rms-nm", type=float, default=5.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = load_polishing_config(args.config)
    options = LoopOptions(args.target_rms_nm, args.max_runs, args.solver or config.polishing.solver)
    rows: list[RunRecord] = []
    started = time.perf_counter()
    with ExitStack() as stack:
        opened = time.perf_counter()
        session = open_session(config, stack)
        opened = time.perf_counter() - opened
        loop = PolishingLoop(config, options, link=session.link, maps=session.maps, tif=session.tif,
                             job_folder=session.job_folder, stop=threading.Event(), target_nm=session.target_nm,
                             on_run=rows.append)
        summary = loop.run()
    total = time.perf_counter() - started
    if args.json:
        for row in rows:
            print(json.dumps(row.to_json()))
        print(json.dumps({**summary.to_json(), "open_s": opened, "total_s": total}))
        return
    print(f"{config.source}: solver {options.solver}, target {options.target_rms_nm:g} nm, "
          f"devices opened in {opened:.1f} s")
    print(f"{'run':>3} {'job':>4} {'before':>8} {'predicted':>9} {'measured':>8} {'ratio':>6} {'dwell s':>8} "
          f"{'solve s':>7} {'run s':>6}")
    for row in rows:
        print(f"{row.run:>3} {row.job_id:>4} {row.rms_before_nm:>8.2f} {row.predicted_rms_nm:>9.2f} "
              f"{row.measured_rms_nm:>8.2f} {row.convergence_ratio:>6.2f} {row.total_dwell_s:>8.0f} "
              f"{row.solve_s:>7.2f} {row.run_s:>6.1f}")
    print(f"{summary.state.phase.value} after {summary.state.runs_done} run(s): {summary.state.reason}")
    print(f"surface RMS per measurement (nm): {' -> '.join(f'{r:.2f}' for r in summary.rms_nm)}; "
          f"campaign {total:.1f} s")


if __name__ == "__main__":
    main()
