"""``wavestack replay FILE.h5``: run the pipeline again on a recording."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from wavestack.cli.command import Command
from wavestack.recording import RecordingReader
from wavestack.recording.replay import recorded_config, replay
from wavestack.config import load_station_config


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack replay``."""
    parser.add_argument("recording", metavar="FILE.h5", help="a recording made by wavestack run --record")
    parser.add_argument("--config", type=Path,
                        help="process with this station file's [processing] instead of the recorded one")
    parser.add_argument("--json", action="store_true", help="one JSON object per line, then a summary")


def run_replay(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Replay a recording; returns the exit status."""
    out = sys.stdout
    count = valid = 0
    worst = worst_pv = 0.0
    compared = compared_pv = 0
    with RecordingReader(args.recording) as reader:
        config = load_station_config(args.config) if args.config else recorded_config(reader, args.recording)
        for result in replay(reader, config, same_settings=args.config is None):
            count += 1
            valid += result.processed.valid
            if result.difference_rms is not None:
                compared += 1
                worst = max(worst, result.difference_rms)
            if result.residual_pv_difference is not None:
                compared_pv += 1
                worst_pv = max(worst_pv, abs(result.residual_pv_difference))
            if args.json:
                out.write(json.dumps(result.to_json()) + "\n")
            else:
                p = result.processed
                state = "valid" if p.valid else f"invalid ({p.reason})"
                fitter = p.choice.kind if p.choice else (p.fitter_kind or "-")
                diff = "" if result.difference_rms is None else f", differs from the recording by {result.difference_rms:.2e} waves rms"
                if result.residual_pv_difference is not None:
                    diff += f", residual pv {p.residual_pv:.4f} waves ({result.residual_pv_difference:+.2e})"
                out.write(f"result {result.index}: {state}, fitter {fitter}{diff}\n")
    summary = {"type": "summary", "results": count, "valid": valid, "compared": compared,
               "max_difference_rms": worst if compared else None, "compared_residual_pv": compared_pv,
               "max_residual_pv_difference": worst_pv if compared_pv else None}
    if args.json:
        out.write(json.dumps(summary) + "\n")
    else:
        pv = (f"; residual pv compared for {compared_pv}, largest difference {worst_pv:.2e} waves" if compared_pv
              else "; residual pv not compared (not in this recording)" if compared else "")
        out.write(f"{count} results replayed ({valid} valid); {compared} compared with the recording, "
                  f"largest difference {worst:.2e} waves rms{pv}\n")
    return 0


COMMAND = Command(
    "replay",
    help="run the pipeline again on a recording (same or other fit settings)",
    description="Recompute every result of a recording made with wavestack run --record.",
    add_arguments=add_replay_arguments, handler=run_replay,
)
