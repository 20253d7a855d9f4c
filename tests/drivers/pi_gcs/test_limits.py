"""Move limits: validation of HexapodLimits, and the property that no accepted move breaks a limit."""

from __future__ import annotations

import doctest
import math

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.pi_gcs import HexapodLimits, driver, error_codes, limits, move_refusals, protocol

AXES = ("X", "Y", "Z", "U", "V", "W")
SOFT = {"X": (-5.0, 5.0), "Y": (-5.0, 5.0), "Z": (-2.0, 2.0), "U": (-1.0, 1.0), "V": (-1.0, 1.0), "W": (-3.0, 3.0)}
TRAVEL = {"X": (-4.0, 6.0), "Y": (-17.0, 17.0), "Z": (-6.5, 6.5), "U": (-14.5, 14.5), "V": (-0.5, 14.5),
          "W": (-25.0, 25.0)}
STEP = {axis: 0.5 for axis in AXES}
values = st.floats(min_value=-30.0, max_value=30.0, allow_nan=False)


@pytest.mark.parametrize("soft, step, fragment", [
    ({"X": (1.0, 1.0)}, {"X": 1.0}, "lower < upper"),
    ({"X": (0.0, math.inf)}, {"X": 1.0}, "finite"),
    ({"X": (0.0, 1.0)}, {"X": 0.0}, "> 0"),
    ({"X": (0.0, 1.0)}, {"Y": 1.0}, "same axes"),
    ({"X Y": (0.0, 1.0)}, {"X Y": 1.0}, "identifier"),
])
def test_bad_limits_name_the_field(soft, step, fragment) -> None:
    with pytest.raises(ValueError, match=fragment):
        HexapodLimits(soft=soft, max_step=step)


def test_limits_are_read_only() -> None:
    limits_ = HexapodLimits(soft=dict(SOFT), max_step=dict(STEP))
    with pytest.raises(TypeError):
        limits_.soft["X"] = (-100.0, 100.0)  # type: ignore[index]


@fuzz_settings(200)
@given(st.fixed_dictionaries({}, optional={axis: values for axis in AXES}),
       st.fixed_dictionaries({axis: st.floats(min_value=-3.0, max_value=3.0) for axis in AXES}))
def test_an_accepted_move_respects_every_limit_and_a_refused_one_breaks_one(target, current) -> None:
    limits_ = HexapodLimits(soft=SOFT, max_step=STEP)
    refusals = move_refusals(target, current, limits_, TRAVEL)
    breaks = {axis for axis, value in target.items()
              if not (TRAVEL[axis][0] <= value <= TRAVEL[axis][1] and SOFT[axis][0] <= value <= SOFT[axis][1]
                      and abs(value - current[axis]) <= STEP[axis])}
    assert {reason.split(":")[0] for reason in refusals} == breaks


@pytest.mark.parametrize("module", [protocol, error_codes, limits, driver], ids=lambda m: m.__name__)
def test_examples_run(module) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
