"""The ``wavestack`` command line: parses arguments and hands each subcommand to its module.

Each command is one module of this package that declares its
:class:`~wavestack.cli.command.Command` (name, help, options, handler); :func:`build_parser`
registers every one of :data:`COMMANDS`. Only this layer prints. Bad input (a file, an option's
value, a path to write) ends in one line on standard error naming the input and exit status 2,
never a traceback; a device failure in one line and exit status 3; an unexpected exception (a bug)
in one line and exit status 1, with the traceback under ``-v``. A malformed command line (unknown
option, missing argument) gets argparse's usage, also status 2.
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
from typing import NoReturn  # noqa: E402

from wavestack import __version__  # noqa: E402
from wavestack.cli import align, analyze, batch, bench, calibrate, fit, plc, polish, replay, run, sim  # noqa: E402
from wavestack.drivers.errors import DeviceError  # noqa: E402
from wavestack.pipeline import InputError  # noqa: E402

EXIT_INTERNAL_ERROR = 1
EXIT_BAD_INPUT = 2
EXIT_DEVICE_ERROR = 3

#: The subcommands (each module declares its own), in the order ``wavestack --help`` lists them.
COMMANDS = tuple(module.COMMAND for module in (run, replay, fit, analyze, bench, sim, plc, polish, align, batch,
                                                  calibrate))

__all__ = ["COMMANDS", "EXIT_BAD_INPUT", "EXIT_DEVICE_ERROR", "EXIT_INTERNAL_ERROR", "build_parser", "error_line", "main",
           "one_line", "run_command"]


class _Parser(argparse.ArgumentParser):
    """argparse with one line for a bad option value (the usage stays for a malformed command line)."""

    def error(self, message: str) -> NoReturn:
        if message.startswith("argument "):  # one option's value: say which and what was expected
            self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {one_line(message)} (see '{self.prog} --help')\n")
        super().error(message)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = _Parser(
        prog="wavestack",
        description="Live wavefront metrology: fit Zernike terms to measured maps.",
    )
    parser.add_argument("--version", action="version", version=f"wavestack {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="log progress to stderr (and the traceback of an internal error)")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.register(commands)
    return parser


def one_line(text: str) -> str:
    """``text`` on one line (runs of white space, newlines included, become one space)."""
    return " ".join(text.split())


def _named_inputs(args: argparse.Namespace) -> list[str]:
    """Every path-like value of the command line (strings and paths, also inside lists)."""
    values: list[object] = []
    for value in vars(args).values():
        values.extend(value if isinstance(value, (list, tuple)) else [value])
    return [str(v) for v in values if isinstance(v, (str, os.PathLike)) and str(v)]


def error_line(args: argparse.Namespace, error: BaseException) -> str:
    """The one-line message of an expected failure, naming the input it is about.

    A message that starts with an input of the command line (``map.npy: ...``) is kept; any
    other gets the command's subject (its main input) as a prefix.
    """
    text = one_line(str(error)) or type(error).__name__
    subject_of = getattr(args, "subject", None)
    subject = subject_of(args) if subject_of is not None else None
    if subject and not any(text.startswith(f"{name}:") or text.startswith(f"{name} ") for name in _named_inputs(args)):
        text = f"{subject}: {text}"
    return text


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0, 1 internal error, 2 bad input, 3 device)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    return run_command(args, parser)


def run_command(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run the parsed command's handler; every failure becomes one line and its exit status.

    Exit statuses: 2 bad input (a file, an option's value, a path to write: ``InputError``,
    ``ValueError``, ``MemoryError``, an ``OSError`` naming a file), 3 a device (``DeviceError``),
    1 an internal error (any other exception: a bug; the traceback with ``-v``), 130 interrupted,
    141 the reader of standard output went away.
    """
    log = logging.getLogger(__name__)
    prefix = f"wavestack {args.command}"
    try:
        return int(args.handler(args, parser) or 0)
    except DeviceError as error:
        log.debug("%s failed", args.command, exc_info=True)
        print(f"{prefix}: device error: {one_line(str(error))}", file=sys.stderr)
        return EXIT_DEVICE_ERROR
    except (InputError, ValueError) as error:
        log.debug("%s failed", args.command, exc_info=True)
        print(f"{prefix}: error: {error_line(args, error)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        log.debug("%s failed", args.command, exc_info=True)
        print(f"{prefix}: error: {error_line(args, MemoryError('not enough memory for this input'))}",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"{prefix}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as error:
        if error.filename is None:
            return _internal_error(prefix, args, error)
        log.debug("%s failed", args.command, exc_info=True)
        print(f"{prefix}: error: {error.filename}: {error.strerror or one_line(str(error))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as error:  # a bug: one line, the traceback with -v
        return _internal_error(prefix, args, error)


def _internal_error(prefix: str, args: argparse.Namespace, error: BaseException) -> int:
    if args.verbose:
        logging.getLogger(__name__).error("internal error", exc_info=error)
    hint = "" if args.verbose else "; run with -v for the traceback"
    print(f"{prefix}: internal error (a bug, please report it): {type(error).__name__}: "
          f"{one_line(str(error))}{hint}", file=sys.stderr)
    return EXIT_INTERNAL_ERROR
