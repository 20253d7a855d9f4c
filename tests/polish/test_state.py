"""The loop's state machine: every phase x every event, the terminal phases, and the check step's verdicts."""

from __future__ import annotations

import itertools

import pytest

from wavestack.pipeline.surface import FormFigures, SpecVerdict, check_form, parse_form_tolerance
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from wavestack.polish.state import (
    TERMINAL_PHASES,
    TRANSITIONS,
    LoopEvent,
    LoopPhase,
    LoopState,
    advance,
    judge_job,
    judge_measurement,
)

P, E = LoopPhase, LoopEvent
# The expected next phase of every working phase for every event, written out by hand (not from
# TRANSITIONS): anything not listed is an unexpected event and must fault.
EXPECTED = {
    (P.MEASURING, E.MEASURED): P.CHECKING, (P.MEASURING, E.UNTRUSTED): P.FAULTED,
    (P.CHECKING, E.AT_TARGET): P.TARGET_MET, (P.CHECKING, E.RUNS_EXHAUSTED): P.MAX_RUNS,
    (P.CHECKING, E.NOT_IMPROVED): P.NOT_IMPROVING, (P.CHECKING, E.NEEDS_WORK): P.SOLVING,
    (P.SOLVING, E.SOLVED): P.PROGRAMMING, (P.SOLVING, E.NO_GAIN): P.NOT_IMPROVING,
    (P.SOLVING, E.AT_FLOOR): P.FLOOR_REACHED,
    (P.PROGRAMMING, E.PROGRAMMED): P.HANDING_OFF,
    (P.HANDING_OFF, E.HANDED_OFF): P.POLISHING, (P.POLISHING, E.MACHINE_DONE): P.MEASURING,
}


@pytest.mark.parametrize(("phase", "event"), list(itertools.product(LoopPhase, LoopEvent)),
                         ids=lambda v: v.value)
def test_every_phase_and_event(phase: LoopPhase, event: LoopEvent) -> None:
    state = LoopState(phase, runs_done=2, reason="before")
    after = advance(state, event, "why")
    if phase in TERMINAL_PHASES:
        assert after == state  # a stopped loop never moves again
    elif event is E.FAULT:
        assert (after.phase, after.reason) == (P.FAULTED, "why")
    elif event is E.STOP:
        assert (after.phase, after.reason) == (P.INTERRUPTED, "why")
    elif (phase, event) in EXPECTED:
        assert after.phase is EXPECTED[(phase, event)]
        assert after.runs_done == 2 + (event is E.MACHINE_DONE)
    else:
        assert after.phase is P.FAULTED
        assert event.value in (after.reason or "") and phase.value in (after.reason or "")
        assert after.runs_done == 2


def test_the_table_is_what_the_tests_expect() -> None:
    working = [p for p in LoopPhase if p not in TERMINAL_PHASES]
    listed = {k: v for k, v in TRANSITIONS.items() if k[1] not in (E.FAULT, E.STOP)}
    assert listed == EXPECTED
    assert all((p, E.FAULT) in TRANSITIONS and (p, E.STOP) in TRANSITIONS for p in working)
    assert not any(p in TERMINAL_PHASES for p, _ in TRANSITIONS)


def test_only_a_trusted_check_leads_to_solving() -> None:
    sources = {phase for (phase, _), following in TRANSITIONS.items() if following is P.SOLVING}
    assert sources == {P.CHECKING}
    assert {event for (phase, event), f in TRANSITIONS.items() if phase is P.MEASURING and f is P.CHECKING} \
        == {E.MEASURED}


def test_a_job_handed_off_is_never_sent_again() -> None:
    # out of POLISHING only by the machine's done (to a new measurement) or a stop
    exits = {f for (phase, _), f in TRANSITIONS.items() if phase is P.POLISHING}
    assert exits == {P.MEASURING, P.FAULTED, P.INTERRUPTED}


@fuzz_settings(200)
@given(st.lists(st.sampled_from(list(LoopEvent)), max_size=40))
def test_any_event_sequence_ends_well_formed(events: list[LoopEvent]) -> None:
    state = LoopState()
    handoffs = 0
    for event in events:
        before = state
        state = advance(state, event)
        if state.phase is P.POLISHING and before.phase is P.HANDING_OFF:
            handoffs += 1
        assert state.runs_done >= before.runs_done
        if before.terminal:
            assert state == before
    assert handoffs >= state.runs_done  # every finished run had its own hand-off


def test_the_check_step_verdicts_in_order() -> None:
    kw = {"target_rms_nm": 5.0, "max_runs": 3}
    assert judge_measurement(5.0, None, 0, **kw)[0] is E.AT_TARGET
    assert judge_measurement(4.0, 3.0, 3, **kw)[0] is E.AT_TARGET  # the target wins over the rest
    assert judge_measurement(20.0, 19.0, 1, **kw)[0] is E.NOT_IMPROVED
    assert judge_measurement(20.0, 20.0, 1, **kw)[0] is E.NOT_IMPROVED
    assert judge_measurement(10.0, 20.0, 3, **kw)[0] is E.RUNS_EXHAUSTED
    assert judge_measurement(10.0, 20.0, 2, **kw)[0] is E.NEEDS_WORK
    assert judge_measurement(40.0, None, 0, **kw)[0] is E.NEEDS_WORK
    assert judge_measurement(float("nan"), None, 0, **kw)[0] is E.FAULT
    # a required improvement of 10 %: 20 -> 18.5 is not enough
    assert judge_measurement(18.5, 20.0, 1, min_improvement=0.1, **kw)[0] is E.NOT_IMPROVED
    assert judge_measurement(17.5, 20.0, 1, min_improvement=0.1, **kw)[0] is E.NEEDS_WORK


def test_the_solve_step_verdicts_in_order() -> None:
    kw = {"floor_tolerance": 0.1, "min_improvement": 0.05}
    # within 10 % of the floor: stop there, even though the job is still predicted to help
    assert judge_job(6.2, 5.9, 5.8, **kw) is E.AT_FLOOR
    assert judge_job(6.38, 5.9, 5.8, **kw) is E.AT_FLOOR  # 5.8 x 1.1 = 6.38: the edge counts
    assert judge_job(6.39, 5.0, 5.8, **kw) is E.SOLVED
    assert judge_job(8.0, 6.0, None, **kw) is E.SOLVED  # no floor estimated: never at the floor
    assert judge_job(6.0, 6.0, None, **kw) is E.NO_GAIN
    assert judge_job(10.0, 9.6, 2.0, **kw) is E.NO_GAIN  # 4 % predicted: below the required 5 %
    assert judge_job(10.0, 9.4, 2.0, **kw) is E.SOLVED
    assert judge_job(10.0, float("nan"), None, **kw) is E.NO_GAIN  # a NaN prediction never polishes


def test_the_floor_is_a_terminal_stop_reached_only_from_solving() -> None:
    assert P.FLOOR_REACHED in TERMINAL_PHASES
    assert {phase for (phase, _), f in TRANSITIONS.items() if f is P.FLOOR_REACHED} == {P.SOLVING}
    stopped = advance(LoopState(P.SOLVING, runs_done=3), E.AT_FLOOR, "floor reached: 6.2 nm")
    assert (stopped.phase, stopped.runs_done, stopped.reason) == (P.FLOOR_REACHED, 3, "floor reached: 6.2 nm")
    assert advance(stopped, E.NEEDS_WORK) == stopped


def _verdict(irr_nm: float) -> SpecVerdict:
    form = FormFigures(sag_nm=100.0, irr_nm=irr_nm, rsi_nm=10.0, rmst_nm=40.0, rmsi_nm=20.0, rmsa_nm=18.0, pv_nm=300.0)
    return check_form(form, parse_form_tolerance("3/1(0.5/0.2)"))  # IRR limit 136.5 nm


def test_with_the_drawing_the_check_stops_when_it_is_met_and_names_the_limiting_quantity() -> None:
    kw = {"target_rms_nm": 5.0, "max_runs": 3}
    event, reason = judge_measurement(40.0, None, 0, verdict=_verdict(100.0), **kw)
    assert event is E.AT_TARGET and "PASS" in reason  # the drawing met: the RMS target does not matter
    event, reason = judge_measurement(4.0, None, 0, verdict=_verdict(200.0), **kw)
    assert event is E.NEEDS_WORK and "FAIL, limiting IRR" in reason  # the RMS is met, the drawing is not
    event, reason = judge_measurement(30.0, 40.0, 3, verdict=_verdict(200.0), **kw)
    assert event is E.RUNS_EXHAUSTED and "limiting IRR" in reason
    event, reason = judge_measurement(41.0, 40.0, 1, verdict=_verdict(200.0), **kw)
    assert event is E.NOT_IMPROVED and "limiting IRR" in reason
