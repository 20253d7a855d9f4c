"""check_program refuses every program that breaks one rule, naming the point, the quantity, the value and the limit."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from wavestack.pipeline.polishing.limits import MachineLimits
from wavestack.pipeline.polishing.machine_program import MachineProgram
from wavestack.pipeline.polishing.program_checks import ProgramRejected, check_program

# Five points 1 mm apart along x, 0.5 s each at 2 mm/s (2 x 0.5 = the 1 mm move): well inside
# LIMITS. Starting from rest needs 2^2 / (2 x 1 mm) = 2 mm/s^2, far under the 1000 allowed.
LIMITS = MachineLimits(10.0, 1000.0, (-10.0, 10.0), (-10.0, 10.0), 5.0, 100.0)
STEP_MM = 1.0


def _arrays() -> dict[str, np.ndarray]:
    return {
        "x_mm": np.arange(5, dtype=float) - 2.0,
        "y_mm": np.zeros(5),
        "dwell_s": np.full(5, 0.5),
        "feed_mm_s": np.full(5, 2.0),
    }


def _program(**changes: Any) -> MachineProgram:
    fields: dict[str, Any] = {**_arrays(), "path": "raster", "step_mm": STEP_MM, "pixel_mm": 1.0}
    fields.update(changes)
    return MachineProgram(**fields)


def _with(name: str, index: int, value: float, **more: Any) -> MachineProgram:
    arrays = _arrays()
    arrays[name][index] = value
    arrays.update(more)
    return _program(**arrays)


def test_the_baseline_program_passes() -> None:
    check_program(_program(), LIMITS)  # every case below breaks exactly one rule of this one


def _consistent(index: int, feed: float) -> dict[str, np.ndarray]:
    """Arrays with the feed at ``index`` changed and its dwell changed to match (1 mm / feed)."""
    arrays = _arrays()
    arrays["feed_mm_s"][index] = feed
    arrays["dwell_s"][index] = STEP_MM / feed
    return arrays


CASES = [
    # (program, point index, quantity, value, limit)
    (lambda: _with("x_mm", 3, math.nan), 3, "x_mm", math.nan, "finite"),
    (lambda: _with("y_mm", 1, math.inf), 1, "y_mm", math.inf, "finite"),
    (lambda: _with("dwell_s", 2, -math.inf), 2, "dwell_s", -math.inf, "finite"),
    (lambda: _with("feed_mm_s", 4, math.nan), 4, "feed_mm_s", math.nan, "finite"),
    (lambda: _with("x_mm", 4, 10.5), 4, "x_mm", 10.5, (-10.0, 10.0)),
    (lambda: _with("y_mm", 0, -11.0), 0, "y_mm", -11.0, (-10.0, 10.0)),
    (lambda: _with("dwell_s", 2, 0.0), 2, "dwell_s", 0.0, "> 0"),
    (lambda: _with("dwell_s", 1, -0.5), 1, "dwell_s", -0.5, "> 0"),
    (lambda: _program(**{**_arrays(), "dwell_s": np.array([0.5, 0.5, 6.0, 0.5, 0.5]),
                         "feed_mm_s": np.array([2.0, 2.0, 1.0 / 6.0, 2.0, 2.0])}),
     2, "dwell_s", 6.0, 5.0),
    (lambda: _with("feed_mm_s", 3, 0.0), 3, "feed_mm_s", 0.0, "> 0"),
    # 12 mm/s is above the 10 allowed, with its dwell 1/12 s matching: only the feed rule breaks
    (lambda: _program(**_consistent(2, 12.0)), 2, "feed_mm_s", 12.0, 10.0),
    # the dwell says 0.5 s, the feed says 1 mm takes 1/3 s: the two disagree
    (lambda: _with("feed_mm_s", 1, 3.0), 1, "feed_mm_s * dwell_s (mm)", 1.5, "the length of the move into the point"),
]


@pytest.mark.parametrize(("make", "index", "quantity", "value", "limit"), CASES)
def test_each_broken_rule_is_named(make: Any, index: int, quantity: str, value: float, limit: object) -> None:
    with pytest.raises(ProgramRejected) as caught:
        check_program(make(), LIMITS)
    error = caught.value
    assert (error.point_index, error.quantity, error.limit) == (index, quantity, limit)
    assert error.value == value or (math.isnan(value) and math.isnan(error.value))
    assert f"point {index}" in str(error) and quantity in str(error)


def test_an_acceleration_jump_between_neighbours_is_refused() -> None:
    # point 2 at 9 mm/s after 2 mm/s on a 1 mm move: (81 - 4) / (2 x 1) = 38.5 mm/s^2
    arrays = _consistent(2, 9.0)
    limits = MachineLimits(10.0, 30.0, (-10.0, 10.0), (-10.0, 10.0), 5.0, 100.0)
    check_program(_program(**_arrays()), limits)  # the baseline is within 30 mm/s^2
    with pytest.raises(ProgramRejected) as caught:
        check_program(_program(**arrays), limits)
    assert caught.value.point_index == 2 and caught.value.quantity == "acceleration_mm_s2"
    assert caught.value.value == pytest.approx((81.0 - 4.0) / 2.0) and caught.value.limit == 30.0


def test_starting_fast_from_rest_is_refused() -> None:
    # the first move at 9 mm/s from rest within one 1 mm step: 81 / 2 = 40.5 mm/s^2
    limits = MachineLimits(10.0, 40.0, (-10.0, 10.0), (-10.0, 10.0), 5.0, 100.0)
    with pytest.raises(ProgramRejected) as caught:
        check_program(_program(**_consistent(0, 9.0)), limits)
    assert caught.value.point_index == 0 and caught.value.value == pytest.approx(40.5)


def test_not_stopping_within_a_step_after_the_last_point_is_refused() -> None:
    # raise the last two feeds to 9 mm/s so only the stop breaks the 40 mm/s^2 bound
    arrays = _consistent(4, 9.0)
    arrays["feed_mm_s"][3], arrays["dwell_s"][3] = 6.0, 1.0 / 6.0
    limits = MachineLimits(10.0, 40.0, (-10.0, 10.0), (-10.0, 10.0), 5.0, 100.0)
    with pytest.raises(ProgramRejected) as caught:
        check_program(_program(**arrays), limits)
    assert caught.value.point_index == 4 and "stopping" in caught.value.quantity
    assert caught.value.value == pytest.approx(81.0 / 2.0)


def test_a_total_above_the_maximum_is_refused_for_the_program() -> None:
    # 5 x 0.5 s = 2.5 s against a 2 s program limit; every point alone is fine
    limits = MachineLimits(10.0, 1000.0, (-10.0, 10.0), (-10.0, 10.0), 5.0, 2.0)
    with pytest.raises(ProgramRejected) as caught:
        check_program(_program(), limits)
    assert caught.value.point_index is None and caught.value.quantity == "total dwell_s"
    assert caught.value.value == pytest.approx(2.5) and caught.value.limit == 2.0


@pytest.mark.parametrize(
    ("changes", "quantity"),
    [
        ({"x_mm": [], "y_mm": [], "dwell_s": [], "feed_mm_s": []}, "point count"),
        ({"dwell_s": np.full(4, 0.5)}, "length of dwell_s"),
        ({"feed_mm_s": np.full(6, 2.0)}, "length of feed_mm_s"),
        ({"y_mm": np.zeros((5, 1))}, "shape of y_mm"),
        ({"path": "zigzag"}, "path"),
        ({"step_mm": 0.0}, "step_mm"),
        ({"pixel_mm": math.nan}, "pixel_mm"),
    ],
)
def test_malformed_programs_are_refused(changes: dict[str, Any], quantity: str) -> None:
    with pytest.raises(ProgramRejected) as caught:
        check_program(_program(**changes), LIMITS)
    assert caught.value.quantity == quantity and caught.value.point_index is None


@fuzz_settings(200)
@given(
    k=st.integers(0, 4),
    rule=st.sampled_from(["nan_dwell", "outside_x", "zero_dwell", "too_long"]),
)
def test_the_first_broken_point_is_the_one_named(k: int, rule: str) -> None:
    value = {"nan_dwell": math.nan, "outside_x": -20.0, "zero_dwell": 0.0, "too_long": 7.0}[rule]
    name = "x_mm" if rule == "outside_x" else "dwell_s"
    with pytest.raises(ProgramRejected) as caught:
        check_program(_with(name, k, value), LIMITS)
    assert caught.value.point_index == k and caught.value.quantity == name


def test_a_program_is_held_read_only() -> None:
    program = _program()
    with pytest.raises(ValueError, match="read-only"):
        program.dwell_s[0] = 0.0
