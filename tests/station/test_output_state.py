"""The PLC output's state machine: every state x event pair against an explicit table."""

from __future__ import annotations

import itertools

import pytest

from wavestack.station.output_state import (
    OutputAction,
    OutputMode,
    OutputState,
    PlcEvent,
    hold_reason,
    transition,
)

M, E = OutputMode, PlcEvent
FAULTS = {E.TRIPPED: M.TRIPPED, E.ESTOP: M.ESTOP, E.NOT_SCANNING: M.NOT_SCANNING, E.NOT_READY: M.NOT_READY,
          E.LINK_DOWN: M.LINK_DOWN}


def expected(mode: OutputMode, start_up_rearm: bool, event: PlcEvent) -> tuple[OutputMode, bool, OutputAction]:
    """The rules written out once more, case by case, independently of the implementation."""
    if event is E.TRIPPED and mode is M.NOT_ARMED and start_up_rearm:
        return M.NOT_ARMED, False, OutputAction.REARM_AT_START_UP  # the one documented start-up re-arm
    if event in FAULTS:
        return FAULTS[event], start_up_rearm, OutputAction.NONE
    if event in (E.HEALTHY, E.BUSY):
        return (mode if mode in (M.NOT_ARMED, M.ARMED) else M.NOT_ARMED), start_up_rearm, OutputAction.NONE
    if event is E.ARMING_RESULT:
        return (M.ARMED if mode is M.NOT_ARMED else mode), start_up_rearm, OutputAction.NONE
    assert event is E.ACCEPTED
    return mode, False, OutputAction.NONE


@pytest.mark.parametrize(("mode", "start_up_rearm", "event"),
                         list(itertools.product(OutputMode, (True, False), PlcEvent)))
def test_every_state_and_event(mode: OutputMode, start_up_rearm: bool, event: PlcEvent) -> None:
    state = OutputState(mode, start_up_rearm)
    after, action = transition(state, event)
    assert (after.mode, after.start_up_rearm, action) == expected(mode, start_up_rearm, event)
    assert state == OutputState(mode, start_up_rearm)  # pure: the old value is unchanged
    assert transition(state, event) == (after, action)  # and deterministic


def test_only_armed_sends_and_every_other_mode_says_why() -> None:
    assert [m for m in OutputMode if OutputState(m).may_send] == [M.ARMED]
    assert all(hold_reason(m) for m in OutputMode if m is not M.ARMED)
    assert "wavestack plc rearm" in hold_reason(M.TRIPPED)


def test_a_trip_after_a_command_is_never_recovered_by_the_station_itself() -> None:
    """From TRIPPED only HEALTHY/BUSY (the PLC re-armed by an operator) leads out; no result or command does."""
    state, _ = transition(OutputState(M.ARMED, True), E.ACCEPTED)
    state, action = transition(state, E.TRIPPED)
    assert state.mode is M.TRIPPED and action is OutputAction.NONE
    for event in PlcEvent:
        after, action = transition(state, event)
        assert action is OutputAction.NONE
        assert after.mode is {E.HEALTHY: M.NOT_ARMED, E.BUSY: M.NOT_ARMED}.get(event, FAULTS.get(event, M.TRIPPED))
    # re-armed by the operator: not armed, then armed only by a result read back against the machine
    state, _ = transition(state, E.HEALTHY)
    assert transition(state, E.ARMING_RESULT)[0].mode is M.ARMED


def test_the_start_up_rearm_happens_at_most_once() -> None:
    state, action = transition(OutputState(), E.TRIPPED)
    assert action is OutputAction.REARM_AT_START_UP and state.mode is M.NOT_ARMED
    state, action = transition(state, E.TRIPPED)
    assert action is OutputAction.NONE and state.mode is M.TRIPPED
