"""The ``wavestack`` command line: parses arguments and hands each subcommand to its module.

Each command is one module of this package that declares its
:class:`~wavestack.cli.command.Command` (name, help, options, handler); :func:`build_parser`
registers every one of :data:`COMMANDS`. Only this layer prints. Bad input ends in one line on standard
error and exit status 2, never a traceback; a device failure in exit status 3; an unknown option
gets argparse's usage error, also status 2.
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
from wavestack.cli import analyze, bench, fit, plc, replay, run, sim  # noqa: E402
from wavestack.drivers.errors import DeviceError  # noqa: E402
from wavestack.pipeline import InputError  # noqa: E402

EXIT_BAD_INPUT = 2
EXIT_DEVICE_ERROR = 3

#: The subcommands (each module declares its own), in the order ``wavestack --help`` lists them.
COMMANDS = tuple(module.COMMAND for module in (run, replay, fit, analyze, bench, sim, plc))

__all__ = ["COMMANDS", "EXIT_BAD_INPUT", "EXIT_DEVICE_ERROR", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = argparse.ArgumentParser(
        prog="wavestack",
        description="Live wavefront metrology: fit Zernike terms to measured maps.",
    )
    parser.add_argument("--version", action="version", version=f"wavestack {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.register(commands)
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

