"""``wavestack polish``: the closed polishing loop — measure, compute the dwell, hand the job off, measure again.

Without ``--config`` it runs the simulated polishing station (``wavestack/config/polishing.toml``,
shipped inside the package): every device simulated and started by the command, the simulated
machine polishing the simulated optic the camera looks at. The station runs on its own thread for
the whole campaign (its PLC heartbeat never pauses); the loop (:mod:`wavestack.polish.loop`) runs
here. Output paths are checked before any device opens; every run is printed (or one JSON line
with ``--json``), recorded (``--record``) and drawn (``--plots``) as it completes.

Exit status: 0 when the campaign ends at the target, at ``--max-runs`` or on a run that did not
improve (the summary says which); 3 when it ends on a fault (one line naming it); 130 when stopped
by Ctrl-C or SIGTERM (the host's heartbeat then stops, and the PLC's watchdog stops a running job).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from contextlib import ExitStack
from pathlib import Path
from typing import TextIO

from wavestack import __version__
from wavestack.cli.arguments import positive_int
from wavestack.cli.command import Command
from wavestack.cli.outputs import check_plots_folder, json_text
from wavestack.cli.signals import stop_on_signals
from wavestack.cli.web_view import add_web_arguments, chain, open_web_view
from wavestack.config.polishing import load_polishing_config
from wavestack.pipeline import InputError
from wavestack.cli.surface_options import tolerance_argument
from wavestack.polish.loop import CampaignSummary, LoopOptions, PolishingLoop
from wavestack.polish.recorder import CampaignRecorder
from wavestack.polish.run_record import RunRecord, run_line
from wavestack.polish.session import open_session
from wavestack.polish.state import LoopPhase
from wavestack.recording import check_recording_path

logger = logging.getLogger(__name__)

EXIT_FAULT = 3
EXIT_INTERRUPTED = 130


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value >= 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def add_polish_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack polish``."""
    parser.add_argument("--config", type=Path, help="polishing station TOML (default: the simulated station)")
    parser.add_argument("--target-rms-nm", type=_non_negative_float, metavar="X",
                        help="stop once the surface RMS is at most X nm (default: [polishing] target_rms_nm)")
    parser.add_argument("--spec", type=tolerance_argument, metavar="TOLERANCE",
                        help="the drawing's form tolerance, e.g. '3/1(0.25/0.1)' (ISO 10110-5, fringes at 546.07 nm "
                             "unless 'lambda = ... nm' follows): stop when the surface meets it, not on the RMS")
    parser.add_argument("--max-runs", type=positive_int, metavar="N", help="most polishing runs (default: config)")
    parser.add_argument("--solver", choices=("fft", "lsq", "bounded"), help="dwell solver (default: [polishing] solver)")
    parser.add_argument("--json", action="store_true", help="one JSON object per run, then a summary")
    parser.add_argument("--record", metavar="FILE.h5", help="record every measurement, job and run (HDF5)")
    parser.add_argument("--plots", metavar="DIR", help="one PNG per run (created if absent)")
    add_web_arguments(parser)


class _Printer:
    """Runs and transitions to standard output: lines, or JSON objects with ``--json``."""

    def __init__(self, stream: TextIO, as_json: bool) -> None:
        self._stream, self._json = stream, as_json

    def run(self, row: RunRecord) -> None:
        self._write(json_text(row.to_json()) if self._json else run_line(row))

    def event(self, phase: str, reason: str) -> None:
        if not self._json:
            self._write(f"  {phase}: {reason}" if reason else f"  {phase}")

    def summary(self, summary: CampaignSummary) -> None:
        if self._json:
            self._write(json_text(summary.to_json()))
            return
        trend = " -> ".join(f"{rms:.2f}" for rms in summary.rms_nm) or "none"
        self._write(f"{summary.state.phase.value} after {summary.state.runs_done} run(s): {summary.state.reason}")
        self._write(f"surface RMS per measurement (nm): {trend}")
        if summary.verdict is not None:
            checks = "; ".join(f"{c.quantity} {'pass' if c.passed else 'FAIL'} ({100 * c.ratio:.0f} % of its limit)"
                               for c in summary.verdict.checks)
            self._write(f"drawing {summary.verdict.summary()}: {checks}")

    def _write(self, line: str) -> None:
        self._stream.write(line + "\n")
        self._stream.flush()


def run_polish(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run one polishing campaign; returns the exit status (module notes)."""
    # every path first: a typo in --record or --plots must not cost opening every device
    record_to = check_recording_path(args.record) if args.record else None
    plots = check_plots_folder(args.plots) if args.plots else None
    config = load_polishing_config(args.config)
    settings = config.polishing
    options = LoopOptions(target_rms_nm=settings.target_rms_nm if args.target_rms_nm is None else args.target_rms_nm,
                          max_runs=args.max_runs or settings.max_runs, solver=args.solver or settings.solver,
                          spec=args.spec)
    printer = _Printer(sys.stdout, args.json)
    stop = threading.Event()
    with ExitStack() as stack, stop_on_signals(stop):
        web = open_web_view(args, stack, "wavestack polish", ordering=config.station.processing.ordering)
        session = open_session(config, stack, sinks=() if web is None else (web,))
        if plots is not None:
            plots.mkdir(exist_ok=True)
        recorder = None
        if record_to is not None:
            camera = session.devices.camera
            recorder = CampaignRecorder(record_to, (camera.height, camera.width), config.text,
                                        {"software_version": __version__, "pixel_mm": settings.pixel_mm,
                                         "wavelength_nm": config.station.station.wavelength_nm,
                                         "reflection_factor": settings.reflection_factor, "solver": options.solver,
                                         "target_rms_nm": options.target_rms_nm})
            # an exception still ends the file in a clear state (close is idempotent)
            stack.callback(recorder.close, "faulted", "the command ended by an error", -1)
        loop = PolishingLoop(config, options, link=session.link, maps=session.maps, tif=session.tif,
                             job_folder=session.job_folder, stop=stop, recorder=recorder, plots=plots,
                             target_nm=session.target_nm, on_run=chain(printer.run, web.add_run if web else None),
                             on_event=chain(printer.event, web.loop_phase if web else None))
        summary = loop.run()
        if web is not None:
            web.end(f"{summary.state.phase.value} after {summary.state.runs_done} run(s): {summary.state.reason}")
        if recorder is not None:
            recorder.close(summary.state.phase.value, summary.state.reason or "", summary.state.runs_done)
    printer.summary(summary)
    if summary.state.phase is LoopPhase.INTERRUPTED:
        return EXIT_INTERRUPTED
    if summary.state.phase is LoopPhase.FAULTED:
        print(f"wavestack polish: device error: {summary.state.reason}", file=sys.stderr)
        return EXIT_FAULT
    return 0


COMMAND = Command(
    "polish",
    help="closed-loop polishing (default: the simulated polishing station): measure, dwell, job, re-measure",
    description="Run polishing campaigns: average live surface maps, compute the dwell map, plan and check the "
                "machine program, hand the job to the machine over Modbus, wait for it, measure again; stop at "
                "the target RMS, at --max-runs, when a run does not improve, or on any fault.",
    add_arguments=add_polish_arguments, handler=run_polish,
    subject=lambda args: str(args.config) if args.config else "the simulated polishing station (default configuration)",
)
