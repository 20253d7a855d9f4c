"""Convergence: from seeded mount errors to lambda/14 at every field point within 5 corrections.

The ranges (uniform): decentre X Y and despace Z within +-0.3 mm, tilts U V within +-0.03 deg.
Why realistic for this design (f = 1.47 m, 240 x 80 mm pupil, secondary at 500 mm): a secondary
placed on its cell by pins or a CMM sits within a few tenths of a millimetre and a few hundredths
of a degree (Gu et al., Opt. Express 23, 25182, 2015 start from 0.1-0.5 mm and 0.01-0.05 deg);
at these ranges the wavefront is 10-60 waves RMS (the moved image's tilt dominates: 0.1-1.6 waves
without it),
far outside the linear range of a single step at some field points, which is what the loop's
re-linearisation must handle.
"""

from __future__ import annotations

import threading
from contextlib import ExitStack

import numpy as np
import pytest

from align_trials import LIMITS, camera_trial, run_trial
from tma_helpers import example
from wavestack.align import AlignPhase, TermFitter
from wavestack.align.loop import AlignmentLoop, AlignOptions
from wavestack.align.session import open_session, options_of
from wavestack.config.align import load_align_config
from wavestack.pipeline.telescope import DOFS, TmaModel

TARGET = 1 / 14  # Marechal


def test_end_to_end_through_the_gcs_simulators() -> None:
    """One trial of the default: PI drivers on both simulators, the station's camera, the CSF-QCM fitter."""
    config = load_align_config()
    lines = []
    with ExitStack() as stack:
        session = open_session(config, stack, noise_waves=0.02)
        loop = AlignmentLoop(**session.loop_arguments(), options=options_of(config), stop=threading.Event(),
                             on_iteration=lines.append)
        summary = loop.run()
        final = session.bench.hexapod_pose()
        mount = session.bench.truth.mount
    assert summary.state.phase is AlignPhase.TARGET_MET, summary.state.reason
    assert summary.state.iterations_done <= 5
    assert max(summary.iterations[-1].rms_waves) <= TARGET
    assert max(summary.iterations[0].rms_waves) > 1.0  # it started misaligned
    for record in summary.iterations[:-1]:  # every correction printed what was sent and read back
        assert record.move is not None and record.read_back is not None and record.estimate is not None
    # the hexapod undid the mount error: to first order the aligned pose is -mount, shifted by the
    # as-built errors of M1 and M3 the hexapod compensates (a few hundredths of a mm, a few
    # thousandths of a degree at [tma.as_built]'s 5 um / 0.0005 deg RMS); the mount is 10x that
    error = np.abs(np.array(final.as_tuple()[:5]) + np.array(mount.as_tuple()[:5]))
    assert np.all(error <= [0.06, 0.06, 0.06, 0.006, 0.006]), error


def _trials(count: int) -> list[tuple[int, str, int, float]]:
    """Model-level trials (the model's maps, no camera) on the in-memory platforms."""
    design, as_built = example()
    options = AlignOptions(max_iterations=5)
    fitter = TermFitter(TmaModel(design).pupil_mask, 22)  # CSF-QCM, built once for all trials
    rows = []
    for seed in range(count):
        summary, hexapod, _ = run_trial(design, as_built, seed, options, fitter=fitter)
        _assert_within_limits(hexapod.moves, LIMITS)
        rows.append((seed, summary.state.phase.value, summary.state.iterations_done,
                     max(summary.iterations[-1].rms_waves)))
    return rows


def _assert_within_limits(moves, limits) -> None:  # noqa: ANN001
    for start, target in moves:  # no move beyond the step or the limits
        for axis, value in target.items():
            assert limits.soft[axis][0] <= value <= limits.soft[axis][1]
            assert abs(value - start[axis]) <= limits.max_step[axis] + 1e-9


@pytest.mark.slow
def test_three_seeded_trials_converge() -> None:
    """Model level: the loop's own convergence without the camera (the default path is the slow test below)."""
    for seed, phase, iterations, rms in _trials(3):
        assert phase == "target-met" and iterations <= 5 and rms <= TARGET, (seed, phase, iterations, rms)


@pytest.mark.slow
@pytest.mark.timeout(900)  # 20 trials of ~8-15 s each (2.5-5 min with the load); the 300 s default is for hangs
def test_nineteen_of_twenty_seeded_trials_through_the_camera_converge(capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's target on the default path: the station's camera, the CSF-QCM fitter, the GCS simulators."""
    config = load_align_config()
    rows = []
    for seed in range(20):
        summary, moves, limits = camera_trial(config, seed)
        _assert_within_limits(moves, limits)
        rows.append((seed, summary.state.phase.value, summary.state.iterations_done,
                     max(summary.iterations[0].rms_waves), max(summary.iterations[-1].rms_waves)))
    with capsys.disabled():
        print("\nseed phase corrections start-RMS final-RMS (worst field, waves)")
        for row in rows:
            print(f"{row[0]:4d} {row[1]:<14} {row[2]:3d} {row[3]:8.3f} {row[4]:.4f}")
    met = [r for r in rows if r[1] == "target-met" and r[2] <= 5 and r[4] <= TARGET]
    assert len(met) >= 19, rows
    assert max(r[3] for r in rows) > 30.0  # the draws span the stated range, not only its easy middle


def test_dofs_are_the_five_observable_axes() -> None:
    assert DOFS == ("X", "Y", "Z", "U", "V")  # W is unobservable (sensitivity module notes)
