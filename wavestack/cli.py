"""The ``wavestack`` command line: parses arguments and hands each subcommand to its module.

Only this layer prints. Bad input ends in one line on standard error and exit status 2, never a
traceback; an unknown option gets argparse's usage error, also status 2.
"""

from __future__ import annotations

import os

# The fits' matrix products are small: a multi-threaded BLAS gains nothing on them, and its
# spinning worker threads took about one of two cores per result in the station benchmark
# (80-104 ms of CPU per carrier result) and stretched fitter builds from 0.1 to 0.3 s. One
# thread unless the user says otherwise; this must run before numpy is imported.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
from collections.abc import Sequence  # noqa: E402

from wavestack import __version__  # noqa: E402
from wavestack.drivers.errors import DeviceError  # noqa: E402
from wavestack.analyze_command import add_analyze_arguments, run_analyze  # noqa: E402
from wavestack.bench_command import add_bench_arguments, run_bench  # noqa: E402
from wavestack.fit_command import add_fit_arguments, run_fit  # noqa: E402
from wavestack.pipeline import InputError  # noqa: E402
from wavestack.replay_command import add_replay_arguments, run_replay  # noqa: E402
from wavestack.run_command import add_run_arguments, run_station  # noqa: E402
from wavestack.sim_command import add_sim_arguments, run_sim  # noqa: E402

EXIT_BAD_INPUT = 2
EXIT_DEVICE_ERROR = 3


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = argparse.ArgumentParser(
        prog="wavestack",
        description="Live wavefront metrology: fit Zernike terms to measured maps.",
    )
    parser.add_argument("--version", action="version", version=f"wavestack {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run = commands.add_parser(
        "run", help="run the station (default: the simulated station): stream, refit, record, drive the PLC",
        description="Run a metrology station: frames -> aperture -> unwrap -> Zernike fit -> results, "
                    "live view or JSON lines, optional recording, removal commands to the polishing PLC.",
    )
    add_run_arguments(run)
    run.set_defaults(handler=run_station)
    replay = commands.add_parser(
        "replay", help="run the pipeline again on a recording (same or other fit settings)",
        description="Recompute every result of a recording made with wavestack run --record.",
    )
    add_replay_arguments(replay)
    replay.set_defaults(handler=run_replay)
    fit = commands.add_parser(
        "fit",
        help="fit Zernike terms to a wavefront map (.npy)",
        description="Fit Zernike terms to a 2-D wavefront map (.npy, NaN outside the aperture).",
    )
    add_fit_arguments(fit)
    fit.set_defaults(handler=run_fit)
    analyze = commands.add_parser(
        "analyze",
        help="interferograms (a phase-shifted set or one carrier frame) or a .dat/.datx file to Zernike terms",
        description="Analyse interferograms or instrument files: phase, aperture, unwrap, fit.",
    )
    add_analyze_arguments(analyze)
    analyze.set_defaults(handler=run_analyze)
    bench = commands.add_parser(
        "bench", help="run a benchmark and print its figures",
        description="Benchmarks that print figures: 'paper' rebuilds the seed paper's tables, 'station' "
                    "measures the simulated station (results per second, latency, stages, aperture change).",
    )
    add_bench_arguments(bench)
    bench.set_defaults(handler=run_bench)
    sim = commands.add_parser(
        "sim", help="run a simulated instrument standalone (pzt, plc)",
        description="Run one simulated instrument on its real transport until Ctrl-C or SIGTERM.",
    )
    add_sim_arguments(sim)
    sim.set_defaults(handler=run_sim)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.handler(args, parser) or 0)
    except DeviceError as error:
        logging.getLogger(__name__).debug("%s failed", args.command, exc_info=True)
        print(f"wavestack {args.command}: device error: {error}", file=sys.stderr)
        return EXIT_DEVICE_ERROR
    except (InputError, ValueError) as error:
        logging.getLogger(__name__).debug("%s failed", args.command, exc_info=True)
        print(f"wavestack {args.command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"wavestack {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
