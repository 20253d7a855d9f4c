"""The alignment loop's machine over every state x event."""

from __future__ import annotations

import itertools

import pytest

from wavestack.align import TERMINAL_PHASES, TRANSITIONS, AlignEvent, AlignPhase, AlignState, advance, judge_iteration


@pytest.mark.parametrize(("phase", "event"), list(itertools.product(AlignPhase, AlignEvent)))
def test_every_phase_and_event(phase: AlignPhase, event: AlignEvent) -> None:
    state = AlignState(phase, 2, 3, "before")
    after = advance(state, event, "why")
    if phase in TERMINAL_PHASES:
        assert after == state  # a stop is final: nothing moves after it
    elif (phase, event) in TRANSITIONS:
        assert after.phase is TRANSITIONS[(phase, event)]
        assert after.reason == "why"
    else:
        assert after.phase is AlignPhase.FAULTED
        assert event.value in (after.reason or "") and phase.value in (after.reason or "")
    # a move is computed only from estimating, which only a check asking for work reaches
    if after.phase is AlignPhase.MOVING_HEXAPOD and phase is not AlignPhase.MOVING_HEXAPOD:
        assert (phase, event) == (AlignPhase.ESTIMATING, AlignEvent.ESTIMATED)
    if after.phase is AlignPhase.ESTIMATING and phase is not AlignPhase.ESTIMATING:
        assert (phase, event) == (AlignPhase.CHECKING, AlignEvent.NEEDS_WORK)
    if event in (AlignEvent.FAULT, AlignEvent.UNTRUSTED) and phase not in TERMINAL_PHASES:
        assert after.phase is AlignPhase.FAULTED and after.halt_on_entry


def test_counters_follow_the_iteration() -> None:
    state = AlignState()
    for _ in range(3):
        state = advance(state, AlignEvent.FIELD_REACHED)
        state = advance(state, AlignEvent.MEASURED)
    assert (state.phase, state.field_index) == (AlignPhase.MOVING_FIELD, 3)
    state = advance(advance(state, AlignEvent.FIELD_REACHED), AlignEvent.ALL_MEASURED)
    for event in (AlignEvent.NEEDS_WORK, AlignEvent.ESTIMATED, AlignEvent.MOVE_SENT, AlignEvent.ON_TARGET,
                  AlignEvent.VERIFIED):
        state = advance(state, event)
    assert (state.phase, state.iterations_done, state.field_index) == (AlignPhase.MOVING_FIELD, 1, 0)


@pytest.mark.parametrize(("rms", "previous", "done", "expected"), [
    ((0.05, 0.07), None, 0, AlignEvent.AT_TARGET),
    ((0.05, 0.08), 0.08, 1, AlignEvent.NOT_IMPROVED),
    ((0.05, 0.08), 0.5, 5, AlignEvent.ITERATIONS_EXHAUSTED),
    ((0.05, 0.08), 0.5, 4, AlignEvent.NEEDS_WORK),
    ((0.05, float("nan")), 0.5, 1, AlignEvent.FAULT),
    ((), None, 0, AlignEvent.FAULT),
])
def test_judge_iteration(rms, previous, done, expected) -> None:
    event, reason = judge_iteration(rms, previous, done, target_rms_waves=1 / 14, max_iterations=5)
    assert event is expected and reason
