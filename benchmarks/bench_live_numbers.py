"""Honest live numbers on the default station, judged against the simulator's truth, and what they cost.

Run:  .venv/bin/python benchmarks/bench_live_numbers.py [--duration-s 300] [--config F.toml] [--json]

Runs the station (the default simulated one unless ``--config``) for ``--duration-s`` seconds with
one extra sink that judges every valid result:

* **PV / RMS**: the residual's peak to valley over its RMS (target: never above 15);
* **fringe order against the truth**: the simulator's true wavefront of the set's first frame on
  the fit grid; a pixel the fit used must lie inside the true aperture and within half a wave of
  the truth (less the median difference: the piston no interferometer measures; the drift over a
  set is ~1e-4 waves). Counts of used pixels outside the true aperture and of wrong order
  (target: 0);
* **error against the truth**: the result's ``truth_error_rms`` (target: no worse than
  0.0005-0.001 waves RMS on the default station);
* **cost of the mask and the clip**: the processor's ``quality`` and ``clip`` stages against the
  whole processing of the result (the sum of its stages) and against the result period
  (1 / rate), medians over the run (target: <= 5 %); also PV and PVr (``statistics``), and the
  median of every stage.

The judging sink renders the truth map on the fit grid (a few ms at 512 x 512) on the station's
thread, so the rate printed is a little below the station's own. BLAS is pinned to one thread as
the command line pins it. The load (``os.getloadavg``) is printed beside the figures.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from contextlib import ExitStack  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.config import StationConfig, load_station_config  # noqa: E402
from wavestack.station import CycleRecord, Station, open_station_devices  # noqa: E402
from wavestack.station.devices import StationDevices  # noqa: E402


@dataclass
class Judge:
    """The sink: every valid result's figures (a few numbers each; no maps are kept)."""

    devices: StationDevices
    step: int
    results: int = 0
    valid: int = 0
    ratios: list[float] = field(default_factory=list)
    truth_errors: list[float] = field(default_factory=list)
    outside: int = 0
    wrong_order: int = 0
    judged_maps: int = 0
    excluded: list[int] = field(default_factory=list)
    clipped: list[int] = field(default_factory=list)
    low_modulation: list[int] = field(default_factory=list)
    untrusted_order: list[int] = field(default_factory=list)
    mask_share: list[float] = field(default_factory=list)
    statistics_share: list[float] = field(default_factory=list)
    processing_ms: list[float] = field(default_factory=list)
    mask_ms: list[float] = field(default_factory=list)
    stage_ms: dict[str, list[float]] = field(default_factory=dict)
    first_ns: int = 0
    last_ns: int = 0

    def __call__(self, record: CycleRecord) -> None:
        result = record.result
        self.results += 1
        self.last_ns = time.time_ns()
        self.first_ns = self.first_ns or self.last_ns
        if not result.valid or result.quality is None:
            return
        self.valid += 1
        self.ratios.append(result.residual_pv / result.residual_rms)
        if result.truth_error_rms is not None:
            self.truth_errors.append(result.truth_error_rms)
        q = result.quality
        self.excluded.append(q.excluded)
        self.clipped.append(q.clipped)
        self.low_modulation.append(q.low_modulation)
        self.untrusted_order.append(q.untrusted_order)
        stages = result.timings_ms
        total = sum(stages.values())
        mask = stages.get("quality", 0.0) + stages.get("clip", 0.0)
        self.processing_ms.append(total)
        for stage, ms in stages.items():
            self.stage_ms.setdefault(stage, []).append(ms)
        self.mask_ms.append(mask)
        self.mask_share.append(mask / total)
        self.statistics_share.append(stages.get("statistics", 0.0) / total)
        self._judge_orders(record)

    def _judge_orders(self, record: CycleRecord) -> None:
        truth = self.devices.truth(record.frames[0]) if record.frames else None
        if truth is None or record.waves is None or getattr(truth, "source", None) is None:
            return
        if truth.source.aperture_revision != truth.aperture_revision:
            return
        true = truth.source.wavefront(truth.time_s, self.step)
        used = np.isfinite(record.waves)
        inside = used & np.isfinite(true)
        self.outside += int(np.count_nonzero(used & ~inside))
        error = record.waves[inside] - true[inside]
        error -= np.median(error)
        self.wrong_order += int(np.count_nonzero(np.abs(error) >= 0.5))
        self.judged_maps += 1


def _figures(judge: Judge, duration_s: float, config: StationConfig) -> dict[str, object]:
    def spread(values: list[float] | list[int]) -> list[float] | None:
        return None if not values else [float(np.min(values)), float(np.median(values)), float(np.max(values))]

    period_ms = (judge.last_ns - judge.first_ns) * 1e-6 / max(judge.results - 1, 1)
    ratios = np.asarray(judge.ratios)
    return {
        "config": config.source, "duration_s": duration_s, "results": judge.results, "valid": judge.valid,
        "results_per_s": judge.results / duration_s, "load_average": list(os.getloadavg()),
        "pv_over_rms": spread(judge.ratios), "results_over_15": int(np.count_nonzero(ratios > 15.0)),
        "maps_judged": judge.judged_maps, "used_pixels_outside_truth": judge.outside,
        "used_pixels_wrong_order": judge.wrong_order, "truth_error_rms": spread(judge.truth_errors),
        "excluded_pixels": spread(judge.excluded), "clipped_pixels": spread(judge.clipped),
        "low_modulation_pixels": spread(judge.low_modulation), "untrusted_order_pixels": spread(judge.untrusted_order),
        "mask_and_clip_ms": spread(judge.mask_ms), "processing_ms": spread(judge.processing_ms),
        "mask_and_clip_share_of_processing": spread(judge.mask_share),
        "mask_and_clip_share_of_period": float(np.median(judge.mask_ms)) / period_ms if judge.mask_ms else None,
        "statistics_share_of_processing": spread(judge.statistics_share), "result_period_ms": period_ms,
        "stage_median_ms": {stage: float(np.median(ms)) for stage, ms in judge.stage_ms.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration-s", type=float, default=300.0)
    parser.add_argument("--config", help="a station file (default: the simulated default station)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    config = load_station_config(args.config)
    with ExitStack() as stack:
        devices = open_station_devices(config, stack)
        judge = Judge(devices, config.processing.fit_decimation)
        station = Station(config, devices)
        try:
            started = time.monotonic()
            station.run(stop=threading.Event(), on_result=judge, duration_s=args.duration_s)
            duration = time.monotonic() - started
        finally:
            station.close()
    figures = _figures(judge, duration, config)
    if args.json:
        print(json.dumps(figures))
        return
    for key, value in figures.items():
        print(f"{key:36s} {value}")


if __name__ == "__main__":
    main()
