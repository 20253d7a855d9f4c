"""One cycle as values: the pure result builder, the records on a result, and the output stage's record."""

from __future__ import annotations

import json
import math
from dataclasses import FrozenInstanceError, dataclass

import numpy as np
import pytest

from wavestack.config import OutputSettings
from wavestack.drivers.frames import Frame
from wavestack.station import (
    ApertureRecord,
    Counters,
    CycleRecord,
    FitDiagnostics,
    Heartbeat,
    InterferometerOutcome,
    OutputRecord,
    PlcOutput,
    ReconstructorDiagnostics,
    SentCommand,
    SlopeOutcome,
    StationResult,
    make_result,
    with_output,
)

FRAMES = (Frame(7, 1_000_000_000, 0, np.zeros((2, 2), np.uint16), {}),
          Frame(8, 1_010_000_000, 0, np.zeros((2, 2), np.uint16), {}))


def _slope_outcome(valid: bool = True) -> SlopeOutcome:
    return SlopeOutcome(
        valid, None if valid else "lenslets: too few lit", np.array([0.0, 0.1, -0.2, 0.3]) if valid else None,
        residual_rms=0.004 if valid else math.nan,
        diagnostics=ReconstructorDiagnostics(condition=3.5, lit_lenslets=90, pupil_lenslets=100),
        aperture_record=ApertureRecord(id=2, changed=True, topology="90 of 100 pupil lenslets lit (12 x 12 grid)",
                                       valid_lenslets=90, valid_pixels=90 * 225),
        aperture_changed=True, timings_s={"centroid": 0.002, "slopes": 0.001})


def test_make_result_from_a_shack_hartmann_outcome() -> None:
    result = make_result(3, FRAMES, _slope_outcome(), ordering="noll", counters=Counters(9, 4, 1),
                         now_ns=1_050_000_000)
    assert result.index == 3 and result.frame_ids == (7, 8) and result.exposure_time_ns == 1_000_000_000
    assert result.latency_ms == pytest.approx(50.0)  # from the first frame's host time to now_ns
    assert result.coefficients == (0.0, 0.1, -0.2, 0.3) and result.valid and result.reason is None
    assert result.fitter == "modal" and not result.fitter_fallback and result.unwrap_path is None
    assert result.timings_ms == pytest.approx({"centroid": 2.0, "slopes": 1.0})
    assert result.aperture_changed and result.output is None and result.truth_rms is None


def test_make_result_from_an_invalid_interferometer_outcome() -> None:
    outcome = InterferometerOutcome(False, "phase: no fringes", timings_s={})
    result = make_result(0, FRAMES[:1], outcome, ordering="ansi", counters=Counters(1, 1, 0), now_ns=1_000_000_000)
    assert not result.valid and result.reason == "phase: no fringes" and result.coefficients == ()
    assert result.fitter is None and result.fitter_diagnostics is None and result.aperture is None
    assert math.isnan(result.residual_rms) and result.normalisation == "rms" and result.ordering == "ansi"
    assert outcome.new_aperture_mask is None


def test_result_json_keeps_the_keys_and_values_of_the_dicts_it_replaced() -> None:
    result = make_result(3, FRAMES, _slope_outcome(), ordering="noll", counters=Counters(9, 4, 1),
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
    assert line["counters"] == {"acquired": 9, "processed": 4, "dropped": 1}
    assert set(line) == {"type", *StationResult.__dataclass_fields__}


def test_the_empty_records_of_an_invalid_result() -> None:
    lost = StationResult.invalid(4, "device: gone", Counters(1, 5, 0), ordering="noll")
    line = lost.to_json()
    assert line["aperture"] == {} and line["fitter_diagnostics"] == {} and line["output"] is None
    assert line["residual_rms"] is None  # NaN is not JSON
    held = OutputRecord(None, SentCommand(False, None, "HELD|INVALID", "device: gone", (0.0,)))
    assert with_output(lost, held).to_json()["output"] == {
        "sent": False, "command_id": None, "status": "HELD|INVALID", "reason": "device: gone", "values_nm": [0.0]}
    assert Heartbeat(False, error="timeout").to_json() == {"heartbeat": False, "error": "timeout"}
    assert FitDiagnostics(12.0, 0, 0.3).to_json() == {"gram_condition": 12.0, "flips": 0, "max_beltrami": 0.3}
    interferometer = ApertureRecord(id=0, changed=False, topology="simply connected", valid_pixels=10, components=1)
    assert interferometer.to_json() == {"id": 0, "changed": False, "topology": "simply connected", "components": 1,
                                        "valid_pixels": 10}


def test_records_are_frozen() -> None:
    record = CycleRecord(StationResult.invalid(0, "x", Counters(0, 0, 0), ordering="noll"))
    with pytest.raises(FrozenInstanceError):
        record.result = None  # type: ignore[misc]
    with pytest.raises(FrozenInstanceError):
        SentCommand(False, None, "OK", None, ()).sent = True  # type: ignore[misc]


@dataclass
class _Status:
    watchdog_tripped: bool = False
    ready: bool = True
    estop: bool = False


class _FakeLink:
    """The three calls the output stage makes, recorded (a stand-in for a PolishingLink)."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, tuple[float, ...], int]] = []

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
    result = make_result(0, frames, outcome, ordering="noll", counters=Counters(1, 1, 0), now_ns=now)
    record = output.send(result)
    scale = 600.0 * settings.surface_factor * settings.gain  # nm of surface per wave of wavefront
    assert record.heartbeat == Heartbeat(True, watchdog_tripped=False, ready=True, estop=False)
    assert record.sent and record.command.command_id == 1 and record.command.status == "OK"
    assert record.command.values_nm == pytest.approx((0.0, 0.0, 0.0, 0.01 * scale, -0.02 * scale))
    assert link.sent == [(1, record.command.values_nm, settings.passes)]
    lost = output.device_lost("device: gone", time.time_ns())
    assert lost.heartbeat is None and not lost.sent and "HELD" in lost.command.status


def test_with_output_measures_the_latency_to_the_end_of_the_send() -> None:
    result = make_result(0, FRAMES, _slope_outcome(), ordering="noll", counters=Counters(1, 1, 0),
                         now_ns=1_050_000_000)
    sent = OutputRecord(None, SentCommand(False, None, "OK", None, ()))
    assert with_output(result, sent).latency_ms == pytest.approx(50.0)
    later = with_output(result, sent, now_ns=1_052_000_000)
    assert later.latency_ms == pytest.approx(52.0) and later.output is sent
    assert with_output(result, None, now_ns=1_052_000_000) is result  # nothing sent: the result as made
