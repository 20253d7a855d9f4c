"""plan_program over random dwell maps and machine limits: what it plans always runs, and runs what was asked.

The properties are checked here from the program's own numbers (positions, feeds, dwells), not
by trusting check_program alone: feed within its limit on every move, the acceleration bound
between neighbours, inside the travel, every dwell at least the floor ``s_k / max_feed`` and > 0,
at least the requested dwell executed, and the requested dwell given back exactly wherever it
is above the floor the limits set.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fuzz import fuzz_settings
from wavestack.pipeline.polishing.grid import GridFrame
from wavestack.pipeline.polishing.limits import MachineLimits
from wavestack.pipeline.polishing.path import PointLattice
from wavestack.pipeline.polishing.program import plan_program
from wavestack.pipeline.polishing.program_checks import ProgramRejected, check_program

# The planner stays 1e-9 (relative) inside the limits and rounding adds a few ulps: checks
# against a limit allow 1e-9, comparisons of dwell 1e-6 (the planner's own margin, and the
# counting threshold, are far smaller).
LIMIT_RTOL = 1e-9
DWELL_RTOL = 1e-6

dwell_values = st.one_of(st.just(0.0), st.floats(1e-4, 5.0))


@st.composite
def cases(draw: st.DrawFn) -> tuple[np.ndarray, GridFrame, MachineLimits, str, int]:
    shape = (draw(st.integers(1, 20)), draw(st.integers(1, 20)))
    dwell = draw(hnp.arrays(np.float64, shape, elements=dwell_values))
    assume(bool(dwell.any()))
    frame = GridFrame(shape, draw(st.floats(0.05, 2.0)))
    half_x = (shape[1] - 1) / 2 * frame.pixel_mm
    half_y = (shape[0] - 1) / 2 * frame.pixel_mm
    limits = MachineLimits(
        max_feed_mm_s=draw(st.floats(1.0, 500.0)),
        max_accel_mm_s2=draw(st.floats(10.0, 1e5)),
        travel_x_mm=(-half_x - 1.0, half_x + 1.0),
        travel_y_mm=(-half_y - 1.0, half_y + 1.0),
        max_dwell_per_point_s=1e9,  # never binding here: rejection has its own tests
        max_total_dwell_s=1e12,
    )
    return dwell, frame, limits, draw(st.sampled_from(["raster", "spiral"])), draw(st.integers(1, 4))


def _segments(x: np.ndarray, y: np.ndarray, step_mm: float) -> np.ndarray:
    return np.concatenate(([step_mm], np.hypot(np.diff(x), np.diff(y))))


@fuzz_settings(200)
@given(case=cases())
def test_every_planned_program_runs_within_the_limits(case: tuple) -> None:
    dwell, frame, limits, path, step_px = case
    program = plan_program(dwell, frame, limits, path=path, step_px=step_px)
    check_program(program, limits)
    x, y, t, v = program.x_mm, program.y_mm, program.dwell_s, program.feed_mm_s
    step_mm = step_px * frame.pixel_mm
    s = _segments(x, y, step_mm)
    assert np.all(t > 0) and np.all(np.isfinite(t))
    assert np.all(v <= limits.max_feed_mm_s)
    # every dwell at least the time of its move at full feed, and feed x dwell = the move
    assert np.all(t >= s / limits.max_feed_mm_s * (1 - LIMIT_RTOL))
    np.testing.assert_allclose(v * t, s, rtol=LIMIT_RTOL)
    # every move at most one lattice step along each axis (nothing crossed that is not a point)
    assert np.all(s[1:] <= math.sqrt(2) * step_mm * (1 + LIMIT_RTOL))
    # path acceleration from rest, between neighbours, and to rest one step after the end
    v2 = np.concatenate(([0.0], v * v, [0.0]))
    d = np.concatenate((s, [step_mm]))
    assert np.all(np.abs(np.diff(v2)) <= 2 * limits.max_accel_mm_s2 * d * (1 + LIMIT_RTOL))
    assert np.all((x >= limits.travel_x_mm[0]) & (x <= limits.travel_x_mm[1]))
    assert np.all((y >= limits.travel_y_mm[0]) & (y <= limits.travel_y_mm[1]))


@fuzz_settings(200)
@given(case=cases())
def test_at_least_the_requested_dwell_is_executed_where_it_was_asked(case: tuple) -> None:
    dwell, frame, limits, path, step_px = case
    program = plan_program(dwell, frame, limits, path=path, step_px=step_px)
    executed = program.dwell_map(frame)
    assert executed.sum() == pytest.approx(program.total_dwell_s, rel=1e-12)
    assert program.total_dwell_s >= dwell.sum() * (1 - 1e-12)
    # per lattice point (the pixels a point stands for), never less than was asked
    lattice = PointLattice(frame.shape, step_px)
    asked, done = lattice.block_sum(dwell), lattice.block_sum(executed)
    assert np.all(done >= asked * (1 - DWELL_RTOL))
    report = program.report
    assert report is not None
    added = report.floor_extra_s + report.accel_extra_s
    assert program.total_dwell_s == pytest.approx(report.requested_dwell_s + added, rel=1e-9)


@fuzz_settings(200)
@given(case=cases())
def test_the_raster_gives_back_the_requested_dwell_above_the_floor(case: tuple) -> None:
    dwell, frame, limits, _, step_px = case
    program = plan_program(dwell, frame, limits, path="raster", step_px=step_px)
    lattice = PointLattice(frame.shape, step_px)
    asked, done = lattice.block_sum(dwell), lattice.block_sum(program.dwell_map(frame))
    step_mm = step_px * frame.pixel_mm
    # On a raster every move is one step. The feed floor is step / max_feed; the acceleration
    # pass never forces a speed below sqrt(2 a step) (the speed reached from rest in one step),
    # so a dwell above step / sqrt(2 a step) is never raised by it either.
    floor = max(step_mm / limits.max_feed_mm_s, step_mm / math.sqrt(2 * limits.max_accel_mm_s2 * step_mm))
    above = asked >= floor * (1 + DWELL_RTOL)
    np.testing.assert_allclose(done[above], asked[above], rtol=DWELL_RTOL)


def test_step_px_sums_the_pixels_a_point_stands_for() -> None:
    # 6 x 6 map of 0.1 s per pixel, step 3: 4 points of 9 pixels = 0.9 s each, above the floor
    frame = GridFrame((6, 6), pixel_mm=1.0)
    limits = MachineLimits(100.0, 1e5, (-4.0, 4.0), (-4.0, 4.0), 10.0, 100.0)
    program = plan_program(np.full((6, 6), 0.1), frame, limits, step_px=3)
    np.testing.assert_allclose(program.dwell_s, 0.9, rtol=DWELL_RTOL)
    assert program.step_mm == 3.0
    # the points stand at the block centres, rows 1 and 4, columns 1 and 4
    assert sorted(set(program.x_mm.round(9).tolist())) == [-1.5, 1.5]
    executed = program.dwell_map(frame)
    assert executed[1, 1] == pytest.approx(0.9, rel=DWELL_RTOL) and executed.sum() == pytest.approx(3.6)


def test_short_dwells_are_raised_to_the_feed_floor_and_reported() -> None:
    # 1 mm pixels at 10 mm/s: no point can take less than 0.1 s; a 0.02 s request gets 0.1 s
    frame = GridFrame((1, 4), pixel_mm=1.0)
    limits = MachineLimits(10.0, 1e6, (-3.0, 3.0), (-1.0, 1.0), 10.0, 100.0)
    dwell = np.array([[1.0, 0.02, 0.0, 1.0]])
    program = plan_program(dwell, frame, limits)
    np.testing.assert_allclose(program.dwell_s, [1.0, 0.1, 0.1, 1.0], rtol=DWELL_RTOL)
    assert program.report.floor_points == 2
    assert program.report.floor_extra_s == pytest.approx((0.1 - 0.02) + 0.1, rel=DWELL_RTOL)
    assert program.report.accel_extra_s == pytest.approx(0.0, abs=1e-9)


def test_a_map_that_does_not_fit_the_travel_is_rejected() -> None:
    frame = GridFrame((11, 11), pixel_mm=1.0)
    limits = MachineLimits(50.0, 1e4, (-4.0, 4.0), (-5.0, 5.0), 10.0, 1e4)
    dwell = np.zeros((11, 11))
    dwell[3:8, 3:8] = 1.0
    plan_program(dwell, frame, limits)  # x from -2 to 2 mm: inside
    dwell[5, 10] = 1.0  # column 10 is at x = +5 mm, beyond the travel's +4
    with pytest.raises(ProgramRejected) as caught:
        plan_program(dwell, frame, limits)
    assert caught.value.quantity == "x_mm" and caught.value.value == pytest.approx(5.0)
    assert caught.value.limit == (-4.0, 4.0)


@fuzz_settings(200)
@given(
    dwell=hnp.arrays(np.float64, (9, 9), elements=dwell_values),
    lo=st.integers(-5, 4),
    width=st.integers(1, 9),
)
def test_a_raster_is_rejected_exactly_when_dwell_lies_outside_the_travel(dwell: np.ndarray, lo: int, width: int) -> None:
    assume(bool(dwell.any()))
    frame = GridFrame((9, 9), pixel_mm=1.0)  # x from -4 to +4 mm
    travel_x = (lo - 0.5, lo + width - 0.5)
    limits = MachineLimits(50.0, 1e4, travel_x, (-10.0, 10.0), 1e9, 1e12)
    x = np.arange(9) - 4.0
    outside = (x < travel_x[0]) | (x > travel_x[1])
    if dwell[:, outside].any():
        with pytest.raises(ProgramRejected, match="x_mm"):
            plan_program(dwell, frame, limits)
    else:
        plan_program(dwell, frame, limits)  # the raster keeps to the columns that hold dwell


def test_a_point_above_its_maximum_dwell_is_rejected() -> None:
    frame = GridFrame((3, 3), pixel_mm=1.0)
    limits = MachineLimits(50.0, 1e4, (-5.0, 5.0), (-5.0, 5.0), 2.0, 100.0)
    dwell = np.zeros((3, 3))
    dwell[0, 2] = 3.0
    with pytest.raises(ProgramRejected) as caught:
        plan_program(dwell, frame, limits)
    assert (caught.value.quantity, caught.value.value, caught.value.limit) == ("dwell_s", 3.0, 2.0)
    assert caught.value.point_index == 0


def test_a_program_longer_than_the_maximum_is_rejected() -> None:
    frame = GridFrame((4, 4), pixel_mm=1.0)
    limits = MachineLimits(50.0, 1e4, (-5.0, 5.0), (-5.0, 5.0), 2.0, 10.0)
    with pytest.raises(ProgramRejected, match="total dwell_s"):
        plan_program(np.ones((4, 4)), frame, limits)  # 16 s against 10 s


def test_a_map_without_dwell_is_rejected() -> None:
    frame = GridFrame((4, 4), pixel_mm=1.0)
    limits = MachineLimits(50.0, 1e4, (-5.0, 5.0), (-5.0, 5.0), 2.0, 10.0)
    with pytest.raises(ProgramRejected, match="holds none"):
        plan_program(np.zeros((4, 4)), frame, limits)


@pytest.mark.parametrize(
    ("dwell", "kwargs", "message"),
    [
        (np.full((4, 4), -1.0), {}, r"dwell_s\[0, 0\]"),
        (np.full((4, 4), np.nan), {}, "finite"),
        (np.ones((3, 4)), {}, "shape"),
        (np.ones(4), {}, "2-D"),
        (np.ones((4, 4)), {"path": "zigzag"}, "path"),
        (np.ones((4, 4)), {"step_px": 0}, "step_px"),
    ],
)
def test_bad_input_is_refused_by_name(dwell: np.ndarray, kwargs: dict, message: str) -> None:
    frame = GridFrame((4, 4), pixel_mm=1.0)
    limits = MachineLimits(50.0, 1e4, (-5.0, 5.0), (-5.0, 5.0), 2.0, 100.0)
    with pytest.raises(ValueError, match=message):
        plan_program(dwell, frame, limits, **kwargs)


def test_dwell_map_refuses_another_grid() -> None:
    frame = GridFrame((4, 4), pixel_mm=1.0)
    limits = MachineLimits(50.0, 1e4, (-5.0, 5.0), (-5.0, 5.0), 2.0, 100.0)
    program = plan_program(np.ones((4, 4)), frame, limits)
    with pytest.raises(ValueError, match="pixel_mm"):
        program.dwell_map(GridFrame((4, 4), pixel_mm=0.5))
    with pytest.raises(ValueError, match="off the grid"):
        program.dwell_map(GridFrame((2, 2), pixel_mm=1.0))
