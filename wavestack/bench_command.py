"""``wavestack bench``: benchmarks that print figures (never timed tests)."""

from __future__ import annotations

import argparse
import json

from wavestack.bench_paper import format_markdown, rows_as_json, run_paper_benchmark
from wavestack.bench_station import add_station_bench_arguments, run_station_bench
from wavestack.paper_apertures import PAPER_APERTURES


def add_bench_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``wavestack bench``."""
    parser.add_argument("target", choices=("paper", "station"),
                        help="paper: the seed paper's Tables 1-3; station: the simulated station's speed")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument(
        "--aperture", action="append", choices=tuple(PAPER_APERTURES),
        help="paper only: only this aperture (repeatable; default: all)",
    )
    station = parser.add_argument_group("station options")
    add_station_bench_arguments(station, json_option=False)  # type: ignore[arg-type]


def run_bench(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Execute ``wavestack bench``; returns the exit status."""
    if args.target == "station":
        if args.aperture:
            parser.error("--aperture belongs to 'bench paper'")
        return run_station_bench(args)
    if args.config is not None:
        parser.error("--config belongs to 'bench station'")
    rows = run_paper_benchmark(tuple(args.aperture) if args.aperture else None)
    if args.json:
        print(json.dumps({"benchmark": "paper", "rows": rows_as_json(rows)}))
    else:
        print(format_markdown(rows))
    return 0
