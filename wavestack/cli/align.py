"""``wavestack align``: the closed alignment loop of an off-axis TMA on a PI hexapod.

Without ``--config`` it runs the simulated alignment bench (``wavestack/config/tma-alignment.toml``,
shipped inside the package): both PI controllers
simulated on loopback and started by the command, the as-built telescope with a seeded mount error
the loop does not know. With ``[align] simulated = false`` (a real bench, e.g.
``config/tma-alignment-remote.toml``) it starts nothing simulated: the controllers at ``[hexapod]
url`` and ``[field_stage] url``, the station of ``[align] station``, and the fit and RMS without
tilt (docs/alignment.md). Per iteration it prints the RMS per field point, the estimated
misalignment per degree of freedom, the move sent and the position read back (one JSON object per
iteration with ``--json``), and records them with ``--record``.

Exit status: 0 when the run ends at the target, at ``--max-iterations`` or when the wavefront
stops improving (the summary says which); 3 on a fault (one line naming it; the hexapod was
halted); 130 when stopped by Ctrl-C or SIGTERM (halted too).
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import TextIO

from wavestack import __version__
from wavestack.align import TABLE, alignment_history
from wavestack.align.loop import AlignmentLoop, AlignSummary, FieldMeasurement, IterationRecord
from wavestack.align.recorder import AlignRecorder
from wavestack.align.session import open_session, options_of
from wavestack.cli.arguments import positive_int
from wavestack.cli.command import Command
from wavestack.cli.loop_exit import loop_exit
from wavestack.cli.outputs import json_text
from wavestack.cli.signals import stop_on_signals
from wavestack.cli.web_view import add_web_arguments, chain, open_web_view
from wavestack.config.align import load_align_config
from wavestack.pipeline.telescope import DOFS
from wavestack.recording import check_recording_path
from wavestack.web import LiveFeed


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def add_align_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack align``."""
    parser.add_argument("--config", type=Path, help="alignment bench TOML (default: the simulated bench)")
    parser.add_argument("--max-iterations", type=positive_int, metavar="N", help="most corrections (default: config)")
    parser.add_argument("--target-rms-waves", type=_positive_float, metavar="X",
                        help="stop once every field point's RMS is at most X waves (default: config, lambda/14)")
    parser.add_argument("--json", action="store_true", help="one JSON object per iteration, then a summary")
    parser.add_argument("--record", metavar="FILE.h5", help="record every iteration (HDF5)")
    add_web_arguments(parser)


class _Printer:
    def __init__(self, stream: TextIO, as_json: bool) -> None:
        self._stream, self._json = stream, as_json

    def iteration(self, record: IterationRecord) -> None:
        if self._json:
            self._write(json_text(record.to_json()))
            return
        rms = " ".join(f"{r:.4f}" for r in record.rms_waves)
        self._write(f"iteration {record.iteration}: RMS per field point (waves) {rms}")
        if record.estimate is not None:
            self._write("  estimate  " + " ".join(f"{a}={v:+.5f}" for a, v in zip(DOFS, record.estimate)))
        if record.move is not None:
            self._write("  move sent " + " ".join(f"{a}={v:+.5f}" for a, v in record.move.items()))
        if record.read_back is not None:
            self._write("  read back " + " ".join(f"{a}={v:+.5f}" for a, v in record.read_back.items()))

    def summary(self, summary: AlignSummary) -> None:
        if self._json:
            self._write(json_text(summary.to_json()))
            return
        self._write(f"{summary.state.phase.value} after {summary.state.iterations_done} correction(s): "
                    f"{summary.state.reason}")

    def _write(self, line: str) -> None:
        self._stream.write(line + "\n")
        self._stream.flush()


def _shown_on(feed: LiveFeed, measure: Callable[[int], FieldMeasurement]) -> Callable[[int], FieldMeasurement]:
    """The loop's measurement, each map also shown on the web view."""
    def measured(index: int) -> FieldMeasurement:
        measurement = measure(index)
        feed.show_map(measurement.waves, units="waves", title=f"wavefront at field point {index}")
        return measurement
    return measured


def _history_on(feed: LiveFeed) -> Callable[[IterationRecord], None]:
    """Each iteration shown in the web view's history table."""
    records: list[IterationRecord] = []

    def shown(record: IterationRecord) -> None:
        records.append(record)
        feed.show_history(alignment_history(records))
    return shown


def run_align(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run one alignment; returns the exit status (module notes)."""
    record_to = check_recording_path(args.record) if args.record else None
    config = load_align_config(args.config)
    options = options_of(config, max_iterations=args.max_iterations, target_rms_waves=args.target_rms_waves)
    printer = _Printer(sys.stdout, args.json)
    stop = threading.Event()
    with ExitStack() as stack, stop_on_signals(stop):
        web = open_web_view(args, stack, "wavestack align")
        session = open_session(config, stack)
        recorder = None
        if record_to is not None:
            recorder = AlignRecorder(record_to, config.text, config.design.field_points_deg,
                                     software_version=__version__)
            stack.callback(recorder.close, "faulted", "the command ended by an error", -1, None)

        def on_iteration(record: IterationRecord) -> None:
            printer.iteration(record)
            if recorder is not None:
                recorder.iteration(record)

        arguments = session.loop_arguments()
        if web is not None:
            arguments["measure"] = _shown_on(web, session.measure)
        summary = AlignmentLoop(**arguments, options=options, stop=stop, recorder=recorder,  # type: ignore[arg-type]
                                on_iteration=chain(on_iteration, _history_on(web) if web else None),
                                on_event=web.loop_phase if web else None).run()
        if web is not None:
            web.end(f"{summary.state.phase.value} after {summary.state.iterations_done} correction(s): "
                    f"{summary.state.reason}")
        if recorder is not None:
            recorder.finish(summary)
    printer.summary(summary)
    return loop_exit("align", TABLE, summary.state.phase, summary.state.reason)


COMMAND = Command(
    "align",
    help="closed-loop TMA alignment on a PI hexapod (default: the simulated alignment bench)",
    description="Align an off-axis TMA: measure the wavefront at every field point, estimate the aligned mirror's "
                "misalignment from the design model's sensitivity matrix, move the hexapod, wait, verify; stop at "
                "the target RMS at every field point, at --max-iterations, when it stops improving, or on a fault.",
    add_arguments=add_align_arguments, handler=run_align,
    subject=lambda args: str(args.config) if args.config else "the simulated alignment bench (default configuration)",
)
