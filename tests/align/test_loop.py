"""The loop's stops on in-memory platforms: operator stop, not improving, a stale measurement, max iterations."""

from __future__ import annotations

import threading
import time

import numpy as np

from align_trials import LIMITS, STAGE, MemoryPlatform
from tma_helpers import example
from wavestack.align import AlignPhase, TermFitter
from wavestack.align.loop import AlignmentLoop, AlignOptions, FieldMeasurement
from wavestack.pipeline.telescope import HexapodPose, TmaModel

DESIGN, AS_BUILT = example()
MODEL = TmaModel(DESIGN)
FITTER = TermFitter(MODEL.pupil_mask, 15)
TRUTH = TmaModel(DESIGN, AS_BUILT, mount=HexapodPose(0.1, -0.05, 0.1, 0.01, -0.005, 0.0))


def _loop(measure_of, options=AlignOptions(), stop=None, on_event=None):
    hexapod, stage = MemoryPlatform(LIMITS), MemoryPlatform(STAGE)
    fields = DESIGN.field_points_deg
    loop = AlignmentLoop(design_model=MODEL.wavefront, fields=fields,
                         field_positions=[{"1": 10 * fx, "2": 10 * fy} for fx, fy in fields], fitter=FITTER,
                         hexapod=hexapod, field_stage=stage, measure=measure_of(hexapod, fields),  # type: ignore[arg-type]
                         options=options, stop=stop or threading.Event(), on_event=on_event)
    return loop.run(), hexapod


def _true(hexapod, fields):
    def measure(index):
        p = hexapod.position()
        pose = HexapodPose(p["X"], p["Y"], p["Z"], p["U"], p["V"], p["W"])
        return FieldMeasurement(TRUTH.wavefront(fields[index], pose), time.time_ns())
    return measure


def test_operator_stop_halts_and_interrupts() -> None:
    stop = threading.Event()

    def on_event(phase, reason):
        if phase == "moving-hexapod":
            stop.set()  # as Ctrl-C would, between the estimate and the move
    summary, hexapod = _loop(_true, stop=stop, on_event=on_event)
    assert summary.state.phase is AlignPhase.INTERRUPTED and summary.halted is True
    assert hexapod.stopped == 1 and hexapod.moves == []  # stopped before anything was sent


def test_a_stale_measurement_never_moves_again() -> None:
    def stale(hexapod, fields):
        frozen = time.time_ns()  # every map "exposed" before the first arrival
        def measure(index):
            return FieldMeasurement(TRUTH.wavefront(fields[index], HexapodPose()), frozen)
        return measure
    summary, hexapod = _loop(stale)
    assert summary.state.phase is AlignPhase.FAULTED and "stale" in (summary.state.reason or "")
    assert len(hexapod.moves) == 1 and hexapod.stopped == 1  # the first correction, nothing on stale maps


def test_not_improving_ends_the_run() -> None:
    def frozen(hexapod, fields):  # the hexapod moves but the wavefront does not (a loose mirror)
        def measure(index):
            return FieldMeasurement(TRUTH.wavefront(fields[index], HexapodPose()), time.time_ns())
        return measure
    summary, hexapod = _loop(frozen)
    assert summary.state.phase is AlignPhase.NOT_IMPROVING and summary.halted is None
    assert len(hexapod.moves) == 1


def test_max_iterations_counts_corrections() -> None:
    summary, hexapod = _loop(_true, options=AlignOptions(max_iterations=1, target_rms_waves=1e-6))
    assert summary.state.phase is AlignPhase.MAX_ITERATIONS
    assert summary.state.iterations_done == 1 and len(hexapod.moves) == 1
    rms = [max(r.rms_waves) for r in summary.iterations]
    assert len(rms) == 2 and rms[1] < rms[0] / 3  # the one correction did its work (gain 0.9)
    assert np.isfinite(rms).all()
