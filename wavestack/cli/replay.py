"""``wavestack replay FILE.h5``: run the pipeline again on a recording."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from wavestack.cli.command import Command
from wavestack.cli.outputs import json_text
from wavestack.recording import RecordingReader
from wavestack.recording.replay import ReplayedResult, SkippedSet, recorded_config, replay
from wavestack.config import load_station_config
from wavestack.cli.outputs import check_plots_folder
from wavestack.figures import ReplayCollector, write_replay_figures


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack replay``."""
    parser.add_argument("recording", metavar="FILE.h5", help="a recording made by wavestack run --record")
    parser.add_argument("--config", type=Path,
                        help="process with this station file's [processing] instead of the recorded one")
    parser.add_argument("--json", action="store_true", help="one JSON object per line, then a summary")
    parser.add_argument("--batched-fits", action="store_true",
                        help="fit the maps that share a fitter together (Fitter.fit_many): float32 fitters round "
                             "otherwise than the live run (~1e-6 waves), so off by default")
    parser.add_argument("--plots", metavar="DIR",
                        help="draw the coefficients over time, the latency histogram and the last map into DIR")


#: Exit status when the recording is damaged: its intact part was replayed, the rest reported.
EXIT_DAMAGED = 2


def run_replay(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Replay a recording; returns the exit status (2 when it is damaged, after replaying what is intact)."""
    out = sys.stdout
    tally = _Tally()
    folder = check_plots_folder(args.plots) if args.plots is not None else None
    collector = ReplayCollector()
    with RecordingReader(args.recording) as reader:
        config = load_station_config(args.config) if args.config else recorded_config(reader, args.recording)
        for item in replay(reader, config, same_settings=args.config is None,
                               batched_fits=args.batched_fits):
            if args.json:
                out.write(json_text(item.to_json()) + "\n")
            else:
                out.write(_line(item) + "\n")
            tally.add(item)
            if folder is not None:
                collector.add(item)
        damage, notes = [str(d) for d in reader.damage], list(reader.notes)
        if folder is not None:
            folder.mkdir(exist_ok=True)
            write_replay_figures(collector.series(str(args.recording), reader.results(), reader.conventions), folder)
    summary = tally.summary() | {"damage": damage, "notes": notes}
    if args.json:
        out.write(json_text(summary) + "\n")
    else:
        out.write(tally.text() + "\n")
    out.flush()
    for note in notes:
        print(f"wavestack replay: {args.recording}: note: {note}", file=sys.stderr)
    if damage:
        print(f"wavestack replay: {args.recording}: damaged recording, {tally.skipped} sets not replayed: "
              + "; ".join(damage), file=sys.stderr)
        return EXIT_DAMAGED
    return 0


def _line(item: ReplayedResult | SkippedSet) -> str:
    if isinstance(item, SkippedSet):
        return f"set {item.index} (recorded set {item.position}): not replayed, damaged"
    p = item.processed
    state = "valid" if p.valid else f"invalid ({p.reason})"
    fitter = p.fitter_kind or "-"
    diff = "" if item.difference_rms is None else f", differs from the recording by {item.difference_rms:.2e} waves rms"
    if item.residual_pv_difference is not None:
        diff += f", residual pv {p.residual_pv:.4f} waves ({item.residual_pv_difference:+.2e})"
    after = ", after a damaged set (may differ from the live run)" if item.affected_by_damage else ""
    return f"result {item.index}: {state}, fitter {fitter}{diff}{after}"


class _Tally:
    """Counts of a replay for its summary line."""

    def __init__(self) -> None:
        self.count = self.valid = self.compared = self.compared_pv = self.skipped = self.affected_by_damage = 0
        self.worst = self.worst_pv = 0.0

    def add(self, item: ReplayedResult | SkippedSet) -> None:
        if isinstance(item, SkippedSet):
            self.skipped += 1
            return
        self.count += 1
        self.valid += item.processed.valid
        self.affected_by_damage += item.affected_by_damage
        if item.difference_rms is not None:
            self.compared += 1
            self.worst = max(self.worst, item.difference_rms)
        if item.residual_pv_difference is not None:
            self.compared_pv += 1
            self.worst_pv = max(self.worst_pv, abs(item.residual_pv_difference))

    def summary(self) -> dict[str, object]:
        return {"type": "summary", "results": self.count, "valid": self.valid, "compared": self.compared,
                "max_difference_rms": self.worst if self.compared else None, "compared_residual_pv": self.compared_pv,
                "max_residual_pv_difference": self.worst_pv if self.compared_pv else None, "skipped": self.skipped,
                "affected_by_damage": self.affected_by_damage}

    def text(self) -> str:
        pv = (f"; residual pv compared for {self.compared_pv}, largest difference {self.worst_pv:.2e} waves"
              if self.compared_pv else "; residual pv not compared (not in this recording)" if self.compared else "")
        skipped = (f"; {self.skipped} damaged sets not replayed, {self.affected_by_damage} results after them"
                   if self.skipped else "")
        return (f"{self.count} results replayed ({self.valid} valid); {self.compared} compared with the recording, "
                f"largest difference {self.worst:.2e} waves rms{pv}{skipped}")


COMMAND = Command(
    "replay",
    help="run the pipeline again on a recording (same or other fit settings)",
    description="Recompute every result of a recording made with wavestack run --record. A damaged recording "
                "(truncated, or failing its checksums) replays what is intact, lists the rest, and exits with 2.",
    add_arguments=add_replay_arguments, handler=run_replay,
)
