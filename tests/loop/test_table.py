"""The kernel's state table: fault and stop everywhere, terminal phases never left, the unexpected faults."""

from __future__ import annotations

import itertools

import pytest

from loop_machine import TABLE, TERMINAL, Event, Phase
from wavestack.loop import StateTable


@pytest.mark.parametrize(("phase", "event"), list(itertools.product(Phase, Event)))
def test_every_phase_and_event(phase: Phase, event: Event) -> None:
    step = TABLE.step(phase, event, "why", "kept")
    if phase in TERMINAL:
        assert step == type(step)(phase, "kept", False)  # never leaves, keeps its reason
    elif event is Event.FAULT:
        assert (step.phase, step.reason, step.expected) == (Phase.FAULTED, "why", True)
    elif event is Event.STOP:
        assert (step.phase, step.reason, step.expected) == (Phase.INTERRUPTED, "why", True)
    elif (phase, event) in {(Phase.A, Event.GO), (Phase.B, Event.FINISH)}:
        assert step.expected and step.phase is {Event.GO: Phase.B, Event.FINISH: Phase.DONE}[event]
    else:
        assert (step.phase, step.expected) == (Phase.FAULTED, False)
        assert step.reason == f"unexpected event {event.value!r} while {phase.value} (why)"


def test_a_terminal_phase_keeps_the_last_reason_when_the_event_gives_none() -> None:
    assert TABLE.step(Phase.B, Event.FINISH, None, "almost").reason == "almost"
    assert TABLE.step(Phase.A, Event.GO, None, "old").reason is None  # a working phase starts afresh


def test_a_table_that_leaves_a_terminal_phase_is_refused() -> None:
    with pytest.raises(ValueError, match="never leaves"):
        StateTable.build({(Phase.DONE, Event.GO): Phase.A}, phases=Phase, terminal=TERMINAL, faulted=Phase.FAULTED,
                         interrupted=Phase.INTERRUPTED, fault=Event.FAULT, stop=Event.STOP)
    with pytest.raises(ValueError, match="terminal"):
        StateTable.build({}, phases=Phase, terminal={Phase.DONE}, faulted=Phase.FAULTED,
                         interrupted=Phase.INTERRUPTED, fault=Event.FAULT, stop=Event.STOP)
