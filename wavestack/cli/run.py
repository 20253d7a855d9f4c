"""``wavestack run``: the station — stream, refit, show, record, and drive the polishing PLC.

Without ``--config`` it runs the simulated station (``wavestack/config/default.toml``, shipped inside the
package): every device simulated and started by the command itself. Ctrl-C or SIGTERM stops it
cleanly: the recording is flushed and closed, the devices released, the summary printed.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import TextIO

import numpy as np

from wavestack.cli.arguments import positive_float, positive_int
from wavestack.cli.command import Command
from wavestack.cli.outputs import json_text
from wavestack.cli.signals import stop_on_signals
from wavestack.cli.web_view import add_web_arguments, open_web_view
from wavestack.config import load_station_config
from wavestack.config.station import with_calibration
from wavestack.recording import StationRecorder, check_recording_path, open_recording
from wavestack.station import (
    CycleRecord,
    LiveStats,
    ResultSink,
    Station,
    StationSummary,
    counter_lines,
    open_station_devices,
    render_live_view,
)

def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack run``."""
    parser.add_argument("--config", type=Path, help="station TOML (default: the simulated station)")
    limit = parser.add_mutually_exclusive_group()
    limit.add_argument("--frames", type=positive_int, metavar="N", help="stop after N results")
    limit.add_argument("--duration", type=positive_float, metavar="S", help="stop after S seconds")
    parser.add_argument("--json", action="store_true",
                        help="one JSON object per line (results, then a summary) instead of the live view")
    parser.add_argument("--record", metavar="FILE.h5", help="record frames, apertures and results (HDF5)")
    parser.add_argument("--calibration", type=Path, metavar="CAL.h5",
                        help="subtract this reference calibration from every map (overrides [processing] calibration)")
    add_web_arguments(parser)


class TerminalView:
    """The live view, redrawn in place on a terminal (a block every few seconds otherwise)."""

    def __init__(self, stream: TextIO, ordering: str, interval_s: float = 0.25) -> None:
        self._stream = stream
        self._ordering = ordering
        self._tty = stream.isatty()
        self._interval_s = interval_s if self._tty else 2.0
        self._stats = LiveStats()
        self._drawn_lines = 0
        self._last_draw = 0.0

    def __call__(self, record: CycleRecord) -> None:
        self._stats.add(record.result, time.time_ns())
        if time.monotonic() - self._last_draw >= self._interval_s:
            self.draw()

    def draw(self) -> None:
        lines = render_live_view(self._stats.snapshot(), self._ordering)
        if self._tty and self._drawn_lines:
            self._stream.write(f"\x1b[{self._drawn_lines}F\x1b[J")  # back to the block's start, clear below
        self._stream.write("\n".join(lines) + "\n")
        self._stream.flush()
        self._drawn_lines = len(lines)
        self._last_draw = time.monotonic()


class JsonLines:
    """One ``{"type": "result", ...}`` object per line, flushed at once."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def __call__(self, record: CycleRecord) -> None:
        self._stream.write(json_text(record.result.to_json()) + "\n")
        self._stream.flush()


def _summary_lines(summary: StationSummary) -> list[str]:
    stages = ", ".join(f"{k} {v:.1f}" for k, v in summary.stage_ms.items())
    return [
        f"{summary.results} results ({summary.valid} valid) in {summary.duration_s:.1f} s: "
        f"{summary.results_per_s:.1f}/s, latency p50 {summary.latency_p50_ms:.0f} ms, p99 {summary.latency_p99_ms:.0f} ms",
        *counter_lines(summary.counters),
        f"aperture changes {summary.aperture_changes}; results on a fallback fitter {summary.fallback_results}",
        f"mean ms per stage: {stages}" if stages else "no stage ran",
    ] + ([f"last invalid result: {summary.last_reason}"] if summary.last_reason else [])


def run_station(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run the station until the limit, Ctrl-C or SIGTERM; returns the exit status."""
    # every path first: a typo in --record must not cost opening (and homing) every device
    record_to = check_recording_path(args.record) if args.record else None  # never over a recording
    config = load_station_config(args.config)
    if args.calibration is not None:
        config = with_calibration(config, args.calibration)
    stop = threading.Event()
    out = sys.stdout
    with ExitStack() as stack, stop_on_signals(stop):
        web = open_web_view(args, stack, "wavestack run", ordering=config.processing.ordering)
        devices = open_station_devices(config, stack)
        station = Station(config, devices)
        stack.callback(station.close)
        sinks: list[ResultSink] = []
        if record_to is not None:
            camera = devices.camera
            dtype = np.uint8 if camera.pixel_format == "Mono8" else np.uint16
            recorder = StationRecorder(open_recording(str(record_to), config, (camera.height, camera.width), dtype),
                                       config)
            stack.callback(recorder.close)
            sinks.append(recorder)
        view = JsonLines(out) if args.json else TerminalView(out, config.processing.ordering)
        sinks.append(view)
        if web is not None:  # last: a result is on stdout (and recorded) before the page shows it
            sinks.append(web)

        def on_result(record: CycleRecord) -> None:
            for sink in sinks:
                sink(record)

        summary = station.run(stop=stop, on_result=on_result, max_results=args.frames, duration_s=args.duration)
        if web is not None:
            web.end(f"stopped after {summary.results} results ({summary.valid} valid)")
    if args.json:
        out.write(json_text(summary.to_json()) + "\n")
    else:
        if isinstance(view, TerminalView):
            view.draw()
        out.write("\n".join(_summary_lines(summary)) + "\n")
    out.flush()
    return 0


COMMAND = Command(
    "run",
    help="run the station (default: the simulated station): stream, refit, record, drive the PLC",
    description="Run a metrology station: frames -> aperture -> unwrap -> Zernike fit -> results, "
                "live view or JSON lines, optional recording, removal commands to the polishing PLC.",
    add_arguments=add_run_arguments, handler=run_station,
    subject=lambda args: str(args.config) if args.config else "the simulated station (default configuration)",
)
