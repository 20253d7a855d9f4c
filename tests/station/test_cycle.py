"""One cycle as values: the pure result builder, the records on a result, and the output stage's record."""

from __future__ import annotations

import json
import logging
import math
from dataclasses import FrozenInstanceError, dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from wavestack.config import OutputSettings
from wavestack.drivers.frames import Frame
from wavestack.drivers.plc import MachineOutputs, ResultDisplay, SpecCode
from wavestack.pipeline import InterferometerOutcome
from wavestack.station import (
    ApertureRecord,
    Counters,
    CycleRecord,
    FitDiagnostics,
    FrameCounts,
    Heartbeat,
    OutputRecord,
    PlcOutput,
    ReconstructorDiagnostics,
    SentCommand,
    SetCounts,
    StationResult,
    make_result,
    start_up_hold,
    with_output,
)

from wavestack.pipeline.instrument import SlopeOutcome  # noqa: E402

FRAMES = (Frame(7, 1_000_000_000, 0, np.zeros((2, 2), np.uint16), {}),
          Frame(8, 1_010_000_000, 0, np.zeros((2, 2), np.uint16), {}))
# sets of two frames: 4 processed (8 frames), one frame dropped by the camera ring
FOUR_SETS = Counters(2, FrameCounts(acquired=9, processed=8, dropped=1, pending=0), SetCounts(4, 4, 0, 0))
ONE_SET = Counters(1, FrameCounts(1, 1, 0, 0), SetCounts(1, 1, 0, 0))


def _slope_outcome(valid: bool = True) -> SlopeOutcome:
    return SlopeOutcome(
        valid, None if valid else "lenslets: too few lit", np.array([0.0, 0.1, -0.2, 0.3]) if valid else None,
        residual_rms=0.004 if valid else math.nan, residual_pv=0.021 if valid else math.nan,
        diagnostics=ReconstructorDiagnostics(condition=3.5, lit_lenslets=90, pupil_lenslets=100),
        aperture_record=ApertureRecord(id=2, changed=True, topology="90 of 100 pupil lenslets lit (12 x 12 grid)",
                                       valid_lenslets=90, valid_pixels=90 * 225),
        aperture_changed=True, timings_s={"centroid": 0.002, "slopes": 0.001})


def test_make_result_from_a_shack_hartmann_outcome() -> None:
    result = make_result(3, FRAMES, _slope_outcome(), ordering="noll", counters=FOUR_SETS,
                         now_ns=1_050_000_000)
    assert result.index == 3 and result.frame_ids == (7, 8) and result.exposure_time_ns == 1_000_000_000
    assert result.latency_ms == pytest.approx(50.0)  # from the first frame's host time to now_ns
    assert result.coefficients == (0.0, 0.1, -0.2, 0.3) and result.valid and result.reason is None
    assert result.fitter == "modal" and not result.fitter_fallback and result.unwrap_path is None
    assert result.timings_ms == pytest.approx({"centroid": 2.0, "slopes": 1.0})
    assert result.aperture_changed and result.output is None and result.truth_rms is None
    assert result.residual_rms == 0.004 and result.residual_pv == 0.021 and result.counters is FOUR_SETS


def test_make_result_from_an_invalid_interferometer_outcome() -> None:
    outcome = InterferometerOutcome(False, "phase: no fringes", timings_s={})
    result = make_result(0, FRAMES[:1], outcome, ordering="ansi", counters=ONE_SET, now_ns=1_000_000_000)
    assert not result.valid and result.reason == "phase: no fringes" and result.coefficients == ()
    assert result.fitter is None and result.fitter_diagnostics is None and result.aperture is None
    assert math.isnan(result.residual_rms) and math.isnan(result.residual_pv)
    assert result.normalisation == "rms" and result.ordering == "ansi"
    assert outcome.new_aperture_mask is None


def test_result_json_keeps_the_keys_and_values_of_the_dicts_it_replaced() -> None:
    result = make_result(3, FRAMES, _slope_outcome(), ordering="noll", counters=FOUR_SETS,
                         now_ns=1_050_000_000)
    sent = OutputRecord(Heartbeat(True, watchdog_tripped=False, ready=True, estop=False),
                        SentCommand(True, 5, "CLIPPED", None, (0.0, 1.5)))
    line = json.loads(json.dumps(with_output(result, sent).to_json()))
    assert list(line)[0] == "type" and line["type"] == "result"
    assert line["aperture"] == {"id": 2, "changed": True, "topology": "90 of 100 pupil lenslets lit (12 x 12 grid)",
                                "valid_lenslets": 90, "valid_pixels": 20250}
    assert line["fitter_diagnostics"] == {"condition": 3.5, "lit_lenslets": 90, "pupil_lenslets": 100}
    assert line["output"] == {"heartbeat": True, "watchdog_tripped": False, "ready": True, "estop": False,
                              "sent": True, "command_id": 5, "status": "CLIPPED", "reason": None,
                              "values_nm": [0.0, 1.5]}
    assert line["counters"] == {"frames_per_set": 2,
                                "frames": {"acquired": 9, "processed": 8, "dropped": 1, "pending": 0},
                                "sets": {"assembled": 4, "processed": 4, "dropped": 0, "pending": 0}}
    assert line["residual_rms"] == 0.004 and line["residual_pv"] == 0.021
    assert set(line) == {"type", *StationResult.__dataclass_fields__}


def test_the_empty_records_of_an_invalid_result() -> None:
    lost = StationResult.invalid(4, "device: gone", Counters.zero(1), ordering="noll")
    line = lost.to_json()
    assert line["aperture"] == {} and line["fitter_diagnostics"] == {} and line["output"] is None
    assert line["residual_rms"] is None and line["residual_pv"] is None  # NaN is not JSON
    held = OutputRecord(None, SentCommand(False, None, "HELD|INVALID", "device: gone", (0.0,)))
    assert with_output(lost, held).to_json()["output"] == {
        "sent": False, "command_id": None, "status": "HELD|INVALID", "reason": "device: gone", "values_nm": [0.0]}
    assert Heartbeat(False, error="timeout").to_json() == {"heartbeat": False, "error": "timeout"}
    assert FitDiagnostics(12.0, 0, 0.3).to_json() == {"gram_condition": 12.0, "flips": 0, "max_beltrami": 0.3}
    interferometer = ApertureRecord(id=0, changed=False, topology="simply connected", valid_pixels=10, components=1)
    assert interferometer.to_json() == {"id": 0, "changed": False, "topology": "simply connected", "components": 1,
                                        "valid_pixels": 10}


def test_records_are_frozen() -> None:
    record = CycleRecord(StationResult.invalid(0, "x", Counters.zero(1), ordering="noll"))
    with pytest.raises(FrozenInstanceError):
        record.result = None  # type: ignore[misc]
    with pytest.raises(FrozenInstanceError):
        SentCommand(False, None, "OK", None, ()).sent = True  # type: ignore[misc]


@dataclass
class _Status:
    watchdog_tripped: bool = False
    ready: bool = True
    estop: bool = False
    busy: bool = False
    raw_word: int = 17


class _FakeLink:
    """The calls the output stage makes, recorded (a stand-in for a PolishingLink)."""

    def __init__(self, n_terms: int = 5) -> None:
        self.sent: list[tuple[int, tuple[float, ...], int]] = []
        self.shown: list[ResultDisplay] = []
        self.n_terms = n_terms
        self.register_map = SimpleNamespace(display=object())  # a map with a display block

    def show_result(self, display: ResultDisplay, timeout_s: float) -> None:
        self.shown.append(display)

    def restrict(self, limits: object) -> object:
        return limits

    def next_command_id(self) -> int:
        return len(self.sent) + 1

    def read_outputs(self, timeout_s: float) -> MachineOutputs:
        return MachineOutputs(False, 0, np.zeros(self.n_terms))  # a machine holding nothing yet

    def read_status(self, timeout_s: float) -> _Status:
        return _Status()

    def heartbeat(self, timeout_s: float) -> _Status:
        return _Status()

    def rearm(self, timeout_s: float) -> None:
        raise AssertionError("nothing tripped")

    def send_removal(self, command_id: int, values, passes: int, timeout_s: float) -> None:
        self.sent.append((command_id, tuple(float(v) for v in values), passes))


def test_the_output_stage_returns_what_it_sent() -> None:
    import time

    link = _FakeLink()
    settings = OutputSettings(first_term=4, gain=1.0, max_removal_nm=100.0, max_step_nm=1000.0)
    output = PlcOutput(link, settings, 5, wavelength_nm=600.0, max_age_s=10.0, timeout_s=1.0)  # type: ignore[arg-type]
    now = time.time_ns()
    frames = (Frame(1, now, 0, np.zeros((2, 2), np.uint16), {}),)
    outcome = SlopeOutcome(True, None, np.array([0.0, 0.5, 0.5, 0.01, -0.02]), residual_rms=0.001)
    result = make_result(0, frames, outcome, ordering="noll", counters=ONE_SET, now_ns=now)
    record = output.send(result)
    scale = 600.0 * settings.surface_factor * settings.gain  # nm of surface per wave of wavefront
    assert record.heartbeat == Heartbeat(True, watchdog_tripped=False, ready=True, estop=False, state="NOT_ARMED")  # armed by this very result
    assert record.sent and record.command.command_id == 1 and record.command.status == "OK"
    assert record.command.values_nm == pytest.approx((0.0, 0.0, 0.0, 0.01 * scale, -0.02 * scale))
    assert link.sent == [(1, record.command.values_nm, settings.passes)]
    # the panel: the fit's residual in nm of surface, no surface figures, no drawing on this station
    assert record.displayed and len(link.shown) == 1
    assert link.shown[0] == ResultDisplay(0, True, link.shown[0].residual_rms_nm, None, SpecCode.NO_SPEC)
    assert link.shown[0].residual_rms_nm == pytest.approx(0.001 * 600.0 * settings.surface_factor)
    lost = output.device_lost("device: gone", time.time_ns(), 1)
    assert lost.heartbeat is not None and lost.heartbeat.ok  # a device fault is not a host fault: still beating
    assert not lost.sent and "HELD" in lost.command.status
    assert lost.displayed and link.shown[-1] == ResultDisplay(1, False, 0.0, None, SpecCode.NO_SPEC)


def test_with_output_measures_the_latency_to_the_end_of_the_send() -> None:
    result = make_result(0, FRAMES, _slope_outcome(), ordering="noll", counters=FOUR_SETS,
                         now_ns=1_050_000_000)
    sent = OutputRecord(None, SentCommand(False, None, "OK", None, ()))
    assert with_output(result, sent).latency_ms == pytest.approx(50.0)
    later = with_output(result, sent, now_ns=1_052_000_000)
    assert later.latency_ms == pytest.approx(52.0) and later.output is sent
    assert with_output(result, None, now_ns=1_052_000_000) is result  # nothing sent: the result as made


@pytest.mark.parametrize("valid, has_request, age_s, expected", [
    (True, True, 0.05, None),  # the one case that arms the output
    (True, True, 1.0, None),  # at the limit is still fresh, as for the safety stage
    (True, True, 1.3, "STALE|HELD|NOT_ARMED"),  # the normal start: a slow first result
    (False, False, 0.05, "INVALID|HELD|NOT_ARMED"),  # e.g. an aperture waiting for confirmation
    (True, False, 0.05, "INVALID|HELD|NOT_ARMED"),
    (False, True, 2.0, "INVALID|STALE|HELD|NOT_ARMED"),
    (True, True, math.nan, "STALE|HELD|NOT_ARMED"),
])
def test_start_up_hold_table(valid: bool, has_request: bool, age_s: float, expected: str | None) -> None:
    hold = start_up_hold(valid=valid, has_request=has_request, age_s=age_s, max_age_s=1.0)
    assert (hold[0] if hold else None) == expected
    if hold:
        assert hold[1].startswith("output not armed yet: ")


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [f"{r.name}: {r.getMessage()}" for r in caplog.records if r.levelno >= logging.WARNING]


def test_the_output_is_armed_by_the_first_fresh_result_and_only_then_warns(caplog: pytest.LogCaptureFixture) -> None:
    link = _FakeLink(2)
    settings = OutputSettings(first_term=1, gain=1.0, max_removal_nm=100.0, max_step_nm=1000.0)
    output = PlcOutput(link, settings, 2, wavelength_nm=600.0, max_age_s=1.0, timeout_s=1.0)  # type: ignore[arg-type]
    request = np.array([0.01, 0.02])
    caplog.set_level(logging.INFO)
    # start-up: an invalid result, then the slow first fit (measured 1.26 s ago): held, at INFO
    held = output.publish(None, valid=False, measured_at_s=10.0, now_s=10.1, reason="aperture: confirming")
    stale = output.publish(request, valid=True, measured_at_s=10.0, now_s=11.26, reason=None)
    assert (held.status, stale.status) == ("INVALID|HELD|NOT_ARMED", "STALE|HELD|NOT_ARMED")
    assert not held.sent and not stale.sent and stale.values_nm == (0.0, 0.0) and link.sent == []
    assert _warnings(caplog) == [] and "PLC output held" in caplog.text
    fresh = output.publish(request, valid=True, measured_at_s=12.0, now_s=12.05, reason=None)
    assert fresh.sent and fresh.status == "OK" and "PLC output armed" in caplog.text
    # armed: a stale result is a real fault, and the safety stage says so
    late = output.publish(request, valid=True, measured_at_s=13.0, now_s=14.5, reason=None)
    assert not late.sent and late.status == "STALE|HELD"
    assert [w for w in _warnings(caplog) if "stale" in w] == [
        "wavestack.drivers.safety: safety stage stops forwarding: input stale: measured 1.5 s ago, max_age_s=1; "
        "holding the last output"]


def test_a_device_lost_before_the_output_is_armed_still_warns(caplog: pytest.LogCaptureFixture) -> None:
    output = PlcOutput(_FakeLink(2), OutputSettings(), 2, wavelength_nm=600.0, max_age_s=1.0,  # type: ignore[arg-type]
                       timeout_s=1.0)
    caplog.set_level(logging.INFO)
    lost = output.device_lost("device: camera unplugged", 20_000_000_000, 0)
    assert not lost.sent and "HELD" in lost.command.status and "NOT_ARMED" not in lost.command.status
    assert any("camera unplugged" in w for w in _warnings(caplog))
