"""``wavestack bench``: benchmarks that print figures (never timed tests)."""

from __future__ import annotations

import argparse
from pathlib import Path

from wavestack.bench import (
    PAPER_APERTURES,
    carrier_config,
    figures_json,
    format_figures,
    format_markdown,
    machine_state,
    measure_path,
    rows_as_json,
    run_paper_cases,
    targets,
)
from wavestack.cli.arguments import positive_int
from wavestack.cli.command import Command
from wavestack.cli.outputs import json_text
from wavestack.config import load_station_config
from wavestack.cli.outputs import check_plots_folder
from wavestack.figures import write_paper_figures
from wavestack.pipeline import InputError

# Fewer samples across cannot hold 36 modes on the thinnest paper aperture (the rounded rectangle is
# a quarter as tall as wide): 32 across leaves ~150 pixels, four per mode.
_SMALLEST_SIZE = 32


def add_bench_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``wavestack bench``."""
    parser.add_argument("target", choices=("paper", "station"),
                        help="paper: the seed paper's Tables 1-3; station: the simulated station's speed")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument(
        "--aperture", action="append", choices=tuple(PAPER_APERTURES),
        help="paper only: only this aperture (repeatable; default: all)",
    )
    parser.add_argument("--plots", metavar="DIR",
                        help="paper only: also draw the seed paper's figures into DIR (made if missing)")
    parser.add_argument("--size", type=positive_int, default=512, metavar="N",
                        help="paper only: samples across each aperture's grid (default 512, the paper's)")
    station = parser.add_argument_group("station options")
    station.add_argument("--config", type=Path, help="station TOML (default: the simulated station)")
    station.add_argument("--results", type=positive_int, default=60, metavar="N",
                         help="results measured per path after the warm-up (default 60)")


def run_bench(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Execute ``wavestack bench``; returns the exit status."""
    if args.target == "station":
        for flag, given in (("--aperture", args.aperture), ("--plots", args.plots), ("--size", args.size != 512)):
            if given:
                raise InputError(f"{flag} applies to 'bench paper' only, not to 'bench station'")
        return run_station_bench(args)
    if args.config is not None:
        raise InputError("--config applies to 'bench station' only, not to 'bench paper'")
    if args.size < _SMALLEST_SIZE:
        raise InputError(f"bench paper: --size {args.size}: expected at least {_SMALLEST_SIZE} samples across")
    folder = check_plots_folder(args.plots) if args.plots is not None else None
    cases = run_paper_cases(tuple(args.aperture) if args.aperture else None, args.size, keep_views=folder is not None)
    rows = [case.row for case in cases]
    if folder is not None:
        folder.mkdir(exist_ok=True)
        write_paper_figures([case.views for case in cases if case.views is not None], folder)
    if args.json:
        print(json_text({"benchmark": "paper", "rows": rows_as_json(rows)}))
    else:
        print(format_markdown(rows))
    return 0


def run_station_bench(args: argparse.Namespace) -> int:
    """Measure both paths and print the figures (text, or JSON with ``args.json``); returns 0.

    Raises
    ------
    ValueError
        A configuration without a simulated camera (the benchmark needs the simulated bench).
    """
    config = load_station_config(args.config)
    if not config.camera.simulated or config.optic is None:
        raise ValueError(f"{config.source}: bench station needs the simulated camera ([camera] url = 'sim://u3v')")
    paths = [("carrier", carrier_config(config))] + ([("psi", config)] if config.processing.method == "psi" else [])
    machine = machine_state()
    figures = [measure_path(name, path_config, args.results) for name, path_config in paths]
    if getattr(args, "json", False):
        print(json_text({"benchmark": "station", "config": config.source, "machine": machine.to_json(),
                          "targets": targets(), "paths": figures_json(figures)}))
    else:
        print("\n".join(format_figures(config.source, figures, machine)))
    return 0


COMMAND = Command(
    "bench",
    help="run a benchmark and print its figures",
    description="Benchmarks that print figures: 'paper' rebuilds the seed paper's tables, 'station' "
                "measures the simulated station (results per second, latency, stages, aperture change).",
    add_arguments=add_bench_arguments, handler=run_bench,
    subject=lambda args: str(args.config) if args.config else f"bench {args.target}",
)
