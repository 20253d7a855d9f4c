"""Where the default station's error against the truth comes from: the samples the truth is fitted on.

Run:  .venv/bin/python benchmarks/truth_samples.py [--duration-s 80]

Runs the default simulated station and, for every second valid result, fits the simulator's true
wavefront (at the set's first frame, on the fit grid) with the result's own fitter twice: on
every sample of the fitter (as the station's truth check does) and on the samples the result
used (the quality mask and the spike clip leave some out). Prints, per fitter kind, the error
against each (RMS over the fitted samples, waves), and the same without Noll 1-3 (piston and
tilts). The load (``os.getloadavg``) is printed beside the figures.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import threading  # noqa: E402
from contextlib import ExitStack  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.config import load_station_config  # noqa: E402
from wavestack.station import CycleRecord, Station, open_station_devices  # noqa: E402

_FIGURES = ("the station's truth_error_rms", "truth fitted on every sample", "truth fitted on the samples used",
            "every sample, Noll 4 on", "samples used, Noll 4 on")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration-s", type=float, default=80.0)
    args = parser.parse_args()
    config = load_station_config(None)
    rows: list[tuple[str, ...]] = []
    with ExitStack() as stack:
        devices = open_station_devices(config, stack)
        check = devices.truth_check
        station = Station(config, devices)
        outcomes: dict[int, object] = {}
        process = station.processor.process

        def keep(pixels, **options):  # type: ignore[no-untyped-def]
            outcomes[id(pixels[0])] = outcome = process(pixels, **options)
            return outcome

        station.processor.process = keep  # type: ignore[method-assign]

        def judge(record: CycleRecord) -> None:
            outcome = outcomes.pop(id(record.frames[0].pixels), None) if record.frames else None
            outcomes.clear()
            result = record.result
            if outcome is None or not result.valid or result.truth_error_rms is None or result.index % 2:
                return
            truth = check.capture(record.frames[0]) if check is not None else None
            if truth is None or truth.source.aperture_revision != truth.aperture_revision:
                return
            fitter = outcome.choice.fitter
            true_map = truth.source.wavefront(truth.time_s, config.processing.fit_decimation)
            every = outcome.fit.coefficients - fitter.fit(true_map, nan_policy="omit").coefficients
            used = np.where(np.isnan(outcome.waves), np.nan, true_map)
            same = outcome.fit.coefficients - fitter.fit(used, nan_policy="omit").coefficients
            rows.append((outcome.choice.kind, result.truth_error_rms, fitter.surface_rms(every),
                         fitter.surface_rms(same), float(np.linalg.norm(every[3:])), float(np.linalg.norm(same[3:]))))

        try:
            station.run(stop=threading.Event(), on_result=judge, duration_s=args.duration_s)
        finally:
            station.close()
    print(f"load average {os.getloadavg()}")
    for kind in sorted({row[0] for row in rows}):
        values = np.array([row[1:] for row in rows if row[0] == kind], dtype=np.float64)
        print(f"fitter {kind}: {len(values)} results")
        for k, name in enumerate(_FIGURES):
            v = values[:, k]
            print(f"  {name:34s} median {np.median(v):.5f}  p99 {np.percentile(v, 99):.5f}  max {v.max():.5f}  "
                  f"above 0.001: {int(np.count_nonzero(v > 0.001))}")


if __name__ == "__main__":
    main()
