"""``wavestack batch RECORDING... --out RESULTS``: re-analyse many recordings on Dask."""

from __future__ import annotations

import argparse
import logging
import math
import sys
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from wavestack.cli.arguments import positive_int
from wavestack.cli.command import Command
from wavestack.cli.outputs import json_text
from wavestack.config import load_station_config

if TYPE_CHECKING:  # wavestack.batch loads pyarrow: only when the command runs
    from wavestack.batch import CampaignReport, Progress, RecordingSummary

#: Exit status when some recording was damaged, unsupported or failed (the rest is committed).
EXIT_INCOMPLETE = 2


def add_batch_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack batch``."""
    parser.add_argument("recordings", metavar="RECORDING", nargs="+",
                        help="recordings of wavestack run --record (also polish campaign records)")
    parser.add_argument("--config", type=Path, help="process with this station file's [processing] instead of "
                                                    "each recording's own settings")
    parser.add_argument("--scheduler", metavar="tcp://HOST:8786",
                        help="a running Dask scheduler (default: a local cluster on this machine)")
    parser.add_argument("--workers", type=positive_int, metavar="N",
                        help="worker processes of the local cluster (default: one per CPU)")
    parser.add_argument("--out", type=Path, required=True, metavar="RESULTS",
                        help="results directory (Parquet: results/, summaries/, settings.parquet)")
    parser.add_argument("--resume", action="store_true",
                        help="skip recordings already in RESULTS with the same file and settings")
    parser.add_argument("--json", action="store_true", help="progress and summaries as JSON lines on stdout")


def run_batch(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run the campaign; 0 when every recording was analysed whole, 2 when some were not."""
    import distributed  # noqa: F401 - configures its loggers on import; quietened below

    from wavestack.batch import CampaignReport, ResultsStore, campaign_client, prepare_campaign, run_campaign

    if args.scheduler is not None and args.workers is not None:
        parser.error("--workers sizes the local cluster; a remote cluster's workers are started with dask worker")
    if not getattr(args, "verbose", False):  # distributed (configured on import) logs every connection at INFO
        logging.getLogger("distributed").setLevel(logging.WARNING)
    config_text = load_station_config(args.config).text if args.config else None
    store = ResultsStore(args.out)
    campaign = prepare_campaign(args.recordings, store, config_text=config_text, resume=args.resume)
    view = _View(args.json)
    if campaign.plans:
        with campaign_client(args.scheduler, args.workers) as client:
            report = run_campaign(campaign, store, client, on_progress=view.progress, on_recording=view.recording)
    else:
        report = CampaignReport(resumed=campaign.resumed)
    view.finish(report)
    incomplete = [s for s in report.analysed if s.status != "ok"]
    for summary in incomplete:
        print(f"wavestack batch: {summary.recording}: {summary.status}: {summary.message or summary.damage}",
              file=sys.stderr)
    for line in report.failed:
        print(f"wavestack batch: {line}", file=sys.stderr)
    return EXIT_INCOMPLETE if incomplete or report.failed else 0


class _View:
    """Progress on the terminal (a bar on stderr) or as JSON lines on stdout."""

    def __init__(self, as_json: bool) -> None:
        self._json = as_json
        self._bar = False

    def progress(self, progress: Progress) -> None:
        from wavestack.batch import progress_bar

        if self._json:
            print(json_text(progress.to_json()), flush=True)
        elif sys.stderr.isatty():
            print("\r" + progress_bar(progress), end="", file=sys.stderr, flush=True)
            self._bar = True

    def recording(self, s: RecordingSummary) -> None:
        if self._json:
            print(json_text({"type": "recording", **asdict(s)}), flush=True)
            return
        self._end_bar()
        worst = ("" if math.isnan(s.max_difference_rms)
                 else f", differs from the recording by <= {s.max_difference_rms:.1e} waves rms")
        print(f"{s.recording}: {s.status}, {s.results} results ({s.valid} valid), {s.skipped} sets skipped{worst}")

    def finish(self, r: CampaignReport) -> None:
        self._end_bar()
        totals = {"type": "summary", "analysed": len(r.analysed), "resumed": len(r.resumed), "failed": len(r.failed),
                  "results": sum(s.results for s in r.analysed)}
        if self._json:
            print(json_text(totals | {"resumed_recordings": list(r.resumed)}), flush=True)
        else:
            print(f"{totals['analysed']} recordings analysed ({totals['results']} results), {totals['resumed']} "
                  f"already in the results, {totals['failed']} failed")

    def _end_bar(self) -> None:
        if self._bar:
            print(file=sys.stderr)
            self._bar = False


COMMAND = Command(
    "batch",
    help="re-analyse many recordings on Dask (a local cluster, or --scheduler)",
    description="Recompute every result of many recordings (wavestack run --record; polish campaign records are "
                "refitted) on a Dask cluster, into a Parquet results directory: one row per result and a summary "
                "per recording, each recording committed as it finishes. --resume continues an interrupted "
                "campaign. A damaged recording is analysed as far as it reads and reported (exit 2).",
    add_arguments=add_batch_arguments, handler=run_batch,
)
