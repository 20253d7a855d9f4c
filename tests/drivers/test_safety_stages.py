"""The safety stage's ao-record stages as pure functions (private to ``wavestack.drivers.safety``).

:class:`SafetyStage.update` is tested end to end in ``test_safety.py``; here each stage is called
alone, with the last output passed in, to show that none keeps or changes state.
"""

from __future__ import annotations

import numpy as np

from wavestack.drivers import SafetyLimits, SafetyStatus
from wavestack.drivers.safety import _drive, _invalid_output, _screen_request, _staleness, _step_toward


def _limits(**overrides: object) -> SafetyLimits:
    values: dict[str, object] = dict(lower=[-1.0, -1.0], upper=[1.0, 1.0], max_step=0.25, max_age_s=1.0)
    values.update(overrides)
    return SafetyLimits(**values)  # type: ignore[arg-type]


def test_screen_names_each_rejection() -> None:
    assert _screen_request(np.array([0.0, 0.5]), True, None) == (SafetyStatus.OK, [])
    status, reasons = _screen_request(None, True, "fit failed")
    assert status == SafetyStatus.INVALID and reasons == ["no request (fit failed)"]
    status, reasons = _screen_request(np.array([np.nan, 0.0]), False, None)
    assert status == SafetyStatus.NON_FINITE | SafetyStatus.INVALID
    assert reasons == ["non-finite request on channels [0]", "request marked invalid"]


def test_staleness_reads_only_the_limits_and_the_two_times() -> None:
    limits = _limits()
    assert _staleness(limits, 10.0, 10.5) is None
    assert "input stale" in (_staleness(limits, 10.0, 11.5) or "")
    assert "in the future" in (_staleness(limits, 10.0, 9.0) or "")
    assert "not finite" in (_staleness(limits, float("nan"), 1.0) or "")


def test_invalid_output_holds_or_steps_toward_the_safe_value() -> None:
    last = np.array([0.8, -0.1])
    values, status, reasons = _invalid_output(_limits(), last)
    assert np.array_equal(values, last) and values is not last
    assert status == SafetyStatus.HELD and reasons == ["holding the last output"]
    values, status, reasons = _invalid_output(_limits(invalid_action="safe_value"), last)
    # 0.8 -> 0.0 is more than one step of 0.25; -0.1 -> 0.0 is within one step
    assert np.allclose(values, [0.55, 0.0])
    assert status == SafetyStatus.HELD | SafetyStatus.RATE_LIMITED and reasons == ["moving toward safe_value"]
    assert np.array_equal(last, [0.8, -0.1])  # the caller's last output is untouched


def test_drive_clips_then_rate_limits() -> None:
    last = np.array([0.9, 0.0])
    values, status, reasons = _drive(_limits(), last, np.array([5.0, 0.1]))
    assert np.array_equal(values, [1.0, 0.1])  # clipped to 1.0, which is within one step of 0.9
    assert status == SafetyStatus.CLIPPED
    assert reasons == ["clipped to the drive limits on channels [0]"]
    values, status, _ = _drive(_limits(), last, np.array([-1.0, 0.1]))
    assert np.allclose(values, [0.65, 0.1]) and status == SafetyStatus.RATE_LIMITED


def test_step_toward_is_exact_within_one_step() -> None:
    limits = _limits()
    target = np.array([0.3, -0.2])
    out = _step_toward(limits, np.array([0.1, -0.4]), target)
    assert np.array_equal(out, target)
