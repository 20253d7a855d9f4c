"""The simulated station's truth check: its anchor maps are rendered on the fitted grid only.

The soak (issue 13) runs the default 1024 x 1024 station for 10 minutes; an anchor that rendered
the optic's full-frame float64 map twice (plus a drift temporary each) every 10 s added ~32 MB of
short-lived heap to the station thread for nothing a real station has.
"""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path

import numpy as np

from wavestack.config import load_station_config
from wavestack.pipeline import InterferometerOutcome
from wavestack.station import CycleRecord
from wavestack.station.sim_truth import InterferometerTruthCheck

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"


def _outcome_and_truth(station_factory):
    config = load_station_config(SMALL)
    station, devices = station_factory(replace(config, processing=replace(config.processing, fit_decimation=2)))
    outcomes: list[InterferometerOutcome] = []
    kept: list[tuple[object, InterferometerOutcome]] = []
    process = station.processor.process

    def keep_outcome(frames, **options) -> InterferometerOutcome:
        outcomes.append(process(frames, **options))
        return outcomes[-1]

    station.processor.process = keep_outcome  # type: ignore[method-assign]

    def on_result(record: CycleRecord) -> None:
        if record.result.valid and record.frames and outcomes[-1].choice is not None:
            kept.append((devices.truth(record.frames[0]), outcomes[-1]))

    station.run(stop=threading.Event(), on_result=on_result, max_results=3)
    assert kept, "no valid result with a fitter"
    assert isinstance(devices.truth_check, InterferometerTruthCheck)
    return devices.truth_check, *kept[-1]


def test_an_anchor_fits_maps_made_on_the_fitted_grid_with_the_same_values(station_factory) -> None:
    check, truth, outcome = _outcome_and_truth(station_factory)
    optic = truth.source
    fitter = outcome.choice.fitter
    step = check.fit_decimation
    grid = tuple(-(-n // step) for n in optic.shape)
    fitted: list[np.ndarray] = []
    fit = fitter.fit

    def spy(waves, **options):
        fitted.append(waves)
        return fit(waves, **options)

    fitter.fit = spy  # type: ignore[method-assign]
    check._key = None  # the next comparison re-anchors
    try:
        errors = check.compare(truth, outcome)
    finally:
        del fitter.fit
    assert errors is not None and errors.truth_rms is not None
    assert len(fitted) == 2
    for waves in fitted:  # a slice of a full-frame map is a view whose base is that map
        assert waves.shape == grid and (waves.base is None or waves.base.shape == grid), \
            f"fitted a {waves.shape} map made from a {None if waves.base is None else waves.base.shape} one"
    t0, start, per_second = check._line
    expected = fit(optic.truth(t0).wavefront_waves[::step, ::step], nan_policy="omit").coefficients
    later = fit(optic.truth(t0 + 1.0).wavefront_waves[::step, ::step], nan_policy="omit").coefficients
    # the same values through the same fitter: equal but for the summation order a multi-threaded BLAS
    # picks per call (1e-15 waves seen); a map made on another grid differs by 1e-7 or more
    np.testing.assert_allclose(start, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(per_second, later - expected, rtol=0, atol=1e-12)
