"""The safety stage: limits and rate bound on every output, whatever the input sequence."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.drivers import SafeOutput, SafetyLimits, SafetyStage, SafetyStatus

N = 3
MAX_AGE_S = 1.0


def _limits(action: str = "hold", **overrides: object) -> SafetyLimits:
    fields: dict[str, object] = {
        "lower": [-10.0, 0.0, -1.0],
        "upper": [10.0, 150.0, 1.0],
        "max_step": [1.0, 5.0, 0.25],
        "max_age_s": MAX_AGE_S,
        "invalid_action": action,
        "safe_value": [0.0, 75.0, 0.5],
    }
    fields.update(overrides)
    return SafetyLimits(**fields)  # type: ignore[arg-type]


def _fresh(stage: SafetyStage, requested: object, **kwargs: object) -> SafeOutput:
    """An update whose measurement is 0.1 s old (fresh for max_age_s = 1 s)."""
    return stage.update(requested, measured_at_s=99.9, now_s=100.0, **kwargs)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------ properties
_value = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),  # anything, incl. NaN, inf, +-1e308
    st.floats(min_value=-200.0, max_value=200.0),  # mostly near the limits
    st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0]),
)
_step = st.fixed_dictionaries(
    {
        "requested": st.one_of(st.none(), st.lists(_value, min_size=N, max_size=N)),
        "valid": st.booleans(),
        # age in s: fresh, stale, from the future, or not finite
        "age_s": st.one_of(
            st.floats(min_value=0.0, max_value=0.9),
            st.floats(min_value=1.1, max_value=1e6),
            st.floats(min_value=-1e3, max_value=-0.1),
            st.sampled_from([math.nan, math.inf, -math.inf]),
        ),
    }
)


def _run(stage: SafetyStage, step: dict[str, object], now_s: float) -> SafeOutput:
    age = float(step["age_s"])  # type: ignore[arg-type]
    return stage.update(
        step["requested"],  # type: ignore[arg-type]
        valid=bool(step["valid"]),
        measured_at_s=now_s - age,
        now_s=now_s,
    )


def _input_ok(step: dict[str, object]) -> bool:
    """The stage's forwarding rule restated independently: valid, finite, fresh."""
    requested = step["requested"]
    age = float(step["age_s"])  # type: ignore[arg-type]
    return (
        requested is not None
        and bool(step["valid"])
        and bool(np.all(np.isfinite(np.asarray(requested, dtype=float))))
        and math.isfinite(age)
        and -0.01 <= age <= MAX_AGE_S  # max_future_s defaults to 0.01 s
    )


@settings(max_examples=150, deadline=None)
@given(
    action=st.sampled_from(["hold", "safe_value"]),
    # arbitrary (non-dyadic) steps make last + step round past the bound now and then
    max_step=st.lists(st.floats(0.01, 20.0), min_size=N, max_size=N),
    steps=st.lists(_step, min_size=1, max_size=25),
)
def test_every_output_within_limits_and_rate_bound(
    action: str, max_step: list[float], steps: list[dict[str, object]]
) -> None:
    limits = _limits(action, max_step=max_step)
    stage = SafetyStage(limits)
    previous = stage.last_output
    np.testing.assert_array_equal(previous, limits.safe_value)  # the start value
    for i, step in enumerate(steps):
        out = _run(stage, step, now_s=1000.0 + i)
        # exact comparisons: the stage guarantees both bounds in float64, no tolerance
        assert out.values.shape == (N,)
        assert np.all(out.values >= limits.lower) and np.all(out.values <= limits.upper)
        assert np.all(np.abs(out.values - previous) <= limits.max_step)
        np.testing.assert_array_equal(stage.last_output, out.values)
        assert out.forwarded == _input_ok(step)
        assert (out.status == SafetyStatus.OK) == (out.reason is None)
        if not out.forwarded and action == "hold":
            # invalid input never changes the output under "hold"
            np.testing.assert_array_equal(out.values, previous)
            assert SafetyStatus.HELD in out.status and SafetyStatus.RATE_LIMITED not in out.status
        if not out.forwarded and action == "safe_value":
            # each held update moves toward safe_value: the distance never grows
            assert np.all(np.abs(out.values - limits.safe_value) <= np.abs(previous - limits.safe_value))
        previous = out.values.copy()


@settings(max_examples=100, deadline=None)
@given(
    data=st.data(),
    # Values on a 1/8 grid with |value| < 2**20: every sum and difference of them is exact in
    # float64, so the number of updates is exactly the integer ceil(distance / max_step).
    step_eighths=st.lists(st.integers(1, 64), min_size=N, max_size=N),
)
def test_constant_request_reached_in_ceil_distance_over_step(
    data: st.DataObject, step_eighths: list[int]
) -> None:
    lower_e, upper_e = -800, 800  # limits in eighths
    start_e = data.draw(st.lists(st.integers(lower_e, upper_e), min_size=N, max_size=N), label="start")
    target_e = data.draw(st.lists(st.integers(lower_e, upper_e), min_size=N, max_size=N), label="target")
    limits = SafetyLimits(
        lower=[lower_e / 8] * N,
        upper=[upper_e / 8] * N,
        max_step=[s / 8 for s in step_eighths],
        max_age_s=MAX_AGE_S,
    )
    stage = SafetyStage(limits)
    stage.reset([s / 8 for s in start_e])
    # ceil(distance / max_step) on integers (-(-a // b) is the integer ceiling)
    needed = max(-(-abs(t - s) // m) for s, t, m in zip(start_e, target_e, step_eighths))
    target = np.array(target_e, dtype=float) / 8
    for i in range(needed):
        out = _fresh(stage, target)
        assert out.forwarded
        if i < needed - 1:
            assert not np.array_equal(out.values, target)  # not earlier than the bound allows
    np.testing.assert_array_equal(stage.last_output, target)
    assert _fresh(stage, target).status == SafetyStatus.OK


@settings(max_examples=100, deadline=None)
@given(
    start=st.lists(st.floats(-10.0, 10.0), min_size=N, max_size=N),
    target=st.lists(st.floats(-10.0, 10.0), min_size=N, max_size=N),
    max_step=st.lists(st.floats(0.1, 25.0), min_size=N, max_size=N),
)
def test_arbitrary_float_request_reached_within_one_extra_update(
    start: list[float], target: list[float], max_step: list[float]
) -> None:
    limits = SafetyLimits(lower=[-10.0] * N, upper=[10.0] * N, max_step=max_step, max_age_s=MAX_AGE_S)
    stage = SafetyStage(limits)
    stage.reset(start)
    # With arbitrary floats, k additions of max_step carry k half-ulp roundings, so the last
    # remaining gap can exceed max_step by a few ulps: allow exactly one update beyond the ceiling.
    needed = max(math.ceil(abs(t - s) / m) for s, t, m in zip(start, target, max_step))
    for _ in range(needed + 1):
        _fresh(stage, target)
    np.testing.assert_array_equal(stage.last_output, np.asarray(target))


# ------------------------------------------------------------------------------- examples
def test_fresh_in_range_request_passes_unchanged() -> None:
    stage = SafetyStage(_limits())
    out = _fresh(stage, [0.5, 76.0, 0.4])
    assert out.status == SafetyStatus.OK and out.reason is None and out.forwarded
    np.testing.assert_array_equal(out.values, [0.5, 76.0, 0.4])
    np.testing.assert_array_equal(out.requested, [0.5, 76.0, 0.4])


def test_clipped_to_drive_limits() -> None:
    stage = SafetyStage(_limits())
    stage.reset([10.0, 150.0, 1.0])
    out = _fresh(stage, [11.0, 150.0, 1.0])
    assert out.status == SafetyStatus.CLIPPED
    np.testing.assert_array_equal(out.values, [10.0, 150.0, 1.0])
    assert "channels [0]" in (out.reason or "")


def test_rate_limited_per_channel() -> None:
    stage = SafetyStage(_limits())  # starts at safe_value [0, 75, 0.5]
    out = _fresh(stage, [3.0, 76.0, 0.0])
    assert out.status == SafetyStatus.RATE_LIMITED
    # channel 0 moves max_step 1.0, channel 1 is within its 5.0, channel 2 moves its 0.25
    np.testing.assert_array_equal(out.values, [1.0, 76.0, 0.25])


def test_rounding_overshoot_pulled_back_to_the_bound() -> None:
    # 0.1 + 0.2 rounds to 0.30000000000000004, a step of 0.20000000000000004 > 0.2 in float64
    assert (0.1 + 0.2) - 0.1 > 0.2
    stage = SafetyStage(SafetyLimits(lower=-1.0, upper=1.0, max_step=0.2, max_age_s=1.0))
    stage.reset([0.1])
    out = _fresh(stage, [1.0])
    assert out.status == SafetyStatus.RATE_LIMITED
    assert out.values[0] - 0.1 <= 0.2 and out.values[0] > 0.29  # one ulp below, not a lost step


def test_clipped_and_rate_limited_together() -> None:
    stage = SafetyStage(_limits())
    out = _fresh(stage, [1e9, 75.0, 0.5])
    assert out.status == SafetyStatus.CLIPPED | SafetyStatus.RATE_LIMITED
    np.testing.assert_array_equal(out.values, [1.0, 75.0, 0.5])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_held(bad: float) -> None:
    stage = SafetyStage(_limits())
    stage.reset([2.0, 80.0, 0.0])
    out = _fresh(stage, [0.0, bad, 0.0])
    assert out.status == SafetyStatus.NON_FINITE | SafetyStatus.HELD
    np.testing.assert_array_equal(out.values, [2.0, 80.0, 0.0])
    assert "channels [1]" in (out.reason or "")
    assert np.isnan(out.requested[1]) if math.isnan(bad) else out.requested[1] == bad  # type: ignore[index]


def test_invalid_flag_and_caller_reason_held() -> None:
    stage = SafetyStage(_limits())
    out = _fresh(stage, [1.0, 76.0, 0.5], valid=False, reason="fit residual 40 nm")
    assert out.status == SafetyStatus.INVALID | SafetyStatus.HELD
    assert "fit residual 40 nm" in (out.reason or "")
    np.testing.assert_array_equal(out.values, [0.0, 75.0, 0.5])


def test_missing_request_is_invalid() -> None:
    out = _fresh(SafetyStage(_limits()), None)
    assert out.status == SafetyStatus.INVALID | SafetyStatus.HELD and out.requested is None


@pytest.mark.parametrize(
    ("measured_at_s", "now_s"),
    [(98.0, 100.0), (100.5, 100.0), (math.nan, 100.0), (99.9, math.inf)],
    ids=["old", "future", "nan-measured", "inf-now"],
)
def test_stale_held(measured_at_s: float, now_s: float) -> None:
    stage = SafetyStage(_limits())
    out = stage.update([1.0, 76.0, 0.5], measured_at_s=measured_at_s, now_s=now_s)
    assert out.status == SafetyStatus.STALE | SafetyStatus.HELD
    np.testing.assert_array_equal(out.values, [0.0, 75.0, 0.5])


def test_age_exactly_max_age_is_fresh_and_small_skew_tolerated() -> None:
    stage = SafetyStage(_limits())
    assert stage.update([0.0, 75.0, 0.5], measured_at_s=99.0, now_s=100.0).status == SafetyStatus.OK
    assert stage.update([0.0, 75.0, 0.5], measured_at_s=100.005, now_s=100.0).status == SafetyStatus.OK


def test_all_faults_reported_together() -> None:
    out = SafetyStage(_limits()).update([math.nan, 0.0, 0.0], valid=False, measured_at_s=0.0, now_s=100.0)
    expected = SafetyStatus.NON_FINITE | SafetyStatus.INVALID | SafetyStatus.STALE | SafetyStatus.HELD
    assert out.status == expected


def test_safe_value_action_moves_at_max_step_then_recovers() -> None:
    stage = SafetyStage(_limits("safe_value"))
    stage.reset([3.0, 60.0, 0.5])
    first = _fresh(stage, [3.0, 60.0, 0.5], valid=False)
    # toward safe [0, 75, 0.5] by at most [1, 5, 0.25]
    assert first.status == SafetyStatus.INVALID | SafetyStatus.HELD | SafetyStatus.RATE_LIMITED
    np.testing.assert_array_equal(first.values, [2.0, 65.0, 0.5])
    for _ in range(2):
        _fresh(stage, None)
    at_safe = _fresh(stage, None)  # ceil(max(3/1, 15/5)) = 3 updates reach it, the 4th stays
    assert at_safe.status == SafetyStatus.INVALID | SafetyStatus.HELD
    np.testing.assert_array_equal(at_safe.values, [0.0, 75.0, 0.5])
    back = _fresh(stage, [0.5, 75.0, 0.5])
    assert back.status == SafetyStatus.OK and back.forwarded


def test_hold_logs_once_per_fault_episode(caplog: pytest.LogCaptureFixture) -> None:
    stage = SafetyStage(_limits())
    with caplog.at_level("INFO", logger="wavestack.drivers.safety"):
        for _ in range(3):
            _fresh(stage, None)
        _fresh(stage, [0.0, 75.0, 0.5])
    assert [r.levelname for r in caplog.records] == ["WARNING", "INFO"]


def test_outputs_and_limits_are_read_only_copies() -> None:
    limits = _limits()
    stage = SafetyStage(limits)
    request = np.array([0.5, 75.0, 0.5])
    out = _fresh(stage, request)
    request[0] = 99.0
    assert out.requested[0] == 0.5  # type: ignore[index]
    with pytest.raises(ValueError):
        out.values[0] = 5.0
    with pytest.raises(ValueError):
        limits.upper[0] = 1e9
    stage.last_output[0] = 7.0
    assert stage.last_output[0] == 0.5


def test_wrong_shape_raises_before_any_change() -> None:
    stage = SafetyStage(_limits())
    stage.reset([1.0, 70.0, 0.0])
    for bad in ([1.0, 2.0], [[1.0, 2.0, 3.0]], "abc"):
        with pytest.raises(ValueError, match="shape|numbers"):
            _fresh(stage, bad)
    np.testing.assert_array_equal(stage.last_output, [1.0, 70.0, 0.0])
    assert _fresh(stage, [1.0, 70.0, 0.0]).status == SafetyStatus.OK  # not left holding


@pytest.mark.parametrize(
    "values", [[11.0, 70.0, 0.0], [0.0, -0.1, 0.0], [0.0, math.nan, 0.0], [0.0, 0.0]], ids=str
)
def test_reset_refuses_values_outside_limits(values: list[float]) -> None:
    stage = SafetyStage(_limits())
    with pytest.raises(ValueError):
        stage.reset(values)
    np.testing.assert_array_equal(stage.last_output, [0.0, 75.0, 0.5])


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"lower": [-10.0, 150.0, -1.0]}, "upper"),  # lower == upper on channel 1
        ({"upper": [10.0, 150.0]}, "upper"),  # shape disagrees
        ({"lower": [-10.0, math.nan, -1.0]}, "lower"),
        ({"upper": [10.0, math.inf, 1.0]}, "upper"),
        ({"max_step": [1.0, 0.0, 0.25]}, "max_step"),
        ({"max_step": -1.0}, "max_step"),
        ({"max_step": 1e-300}, "max_step"),  # below float64 resolution of the limits
        ({"max_age_s": 0.0}, "max_age_s"),
        ({"max_age_s": math.nan}, "max_age_s"),
        ({"max_future_s": -1.0}, "max_future_s"),
        ({"invalid_action": "continue"}, "invalid_action"),
        ({"safe_value": [0.0, 151.0, 0.0]}, "safe_value"),
        ({"safe_value": [0.0, 75.0]}, "safe_value"),
        ({"lower": [], "upper": [], "max_step": [], "safe_value": []}, "lower"),
    ],
)
def test_limits_construction_errors_name_the_field(overrides: dict[str, object], field: str) -> None:
    with pytest.raises(ValueError, match=f"SafetyLimits.{field}"):
        _limits(**overrides)


def test_scalar_limits_broadcast() -> None:
    limits = SafetyLimits(lower=0.0, upper=[150.0, 150.0], max_step=2.0, max_age_s=0.5)
    assert limits.n_channels == 2
    np.testing.assert_array_equal(limits.max_step, [2.0, 2.0])
    np.testing.assert_array_equal(SafetyStage(limits).last_output, [0.0, 0.0])


# ------------------------------------------------------------------ propose / commit (issue 13)
def test_a_proposal_that_is_never_committed_does_not_move_the_base_of_the_rate_limit() -> None:
    """The PLC refused 50 nm (e-stop): the next proposal still counts from 0, not from 50."""
    stage = SafetyStage(SafetyLimits(lower=-200.0, upper=200.0, max_step=50.0, max_age_s=1.0))
    first = stage.propose([150.0], measured_at_s=0.0, now_s=0.1)
    assert first.values.tolist() == [50.0] and SafetyStatus.RATE_LIMITED in first.status
    np.testing.assert_array_equal(stage.last_output, [0.0])  # refused: nothing committed
    again = stage.propose([150.0], measured_at_s=0.2, now_s=0.3)
    assert again.values.tolist() == [50.0]  # not 100: the machine still holds 0
    stage.commit(again.values)  # acknowledged
    assert stage.propose([150.0], measured_at_s=0.4, now_s=0.5).values.tolist() == [100.0]


@given(st.lists(st.tuples(st.floats(min_value=-500.0, max_value=500.0), st.booleans()), min_size=1, max_size=40))
@settings(max_examples=200, deadline=None)
def test_every_committed_step_is_within_max_step_whatever_was_refused(steps: list[tuple[float, bool]]) -> None:
    stage = SafetyStage(SafetyLimits(lower=-200.0, upper=200.0, max_step=50.0, max_age_s=1.0))
    held = 0.0  # what the machine holds: only acknowledged proposals
    for k, (request, acknowledged) in enumerate(steps):
        out = stage.propose([request], measured_at_s=float(k), now_s=k + 0.1)
        assert abs(out.values[0] - held) <= 50.0 and abs(out.values[0]) <= 200.0
        if acknowledged:
            stage.commit(out.values)
            held = float(out.values[0])
        assert stage.last_output.tolist() == [held]


def test_commit_refuses_values_outside_the_limits_and_keeps_the_last_output() -> None:
    stage = SafetyStage(_limits())
    with pytest.raises(ValueError, match="within \\[lower, upper\\]"):
        stage.commit([0.0, 151.0, 0.0])
    np.testing.assert_array_equal(stage.last_output, [0.0, 75.0, 0.5])
