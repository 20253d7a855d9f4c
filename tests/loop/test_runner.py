"""The kernel's runner: one step per working phase, the operator's stop before any step, every state noted."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, replace

from loop_machine import TABLE, Event, Phase
from wavestack.loop import Transitions, run_machine


@dataclass(frozen=True)
class State:
    phase: Phase = Phase.A
    reason: str | None = None

    @property
    def terminal(self) -> bool:
        return self.phase in TABLE.terminal


def advance(state: State, event: Event, reason: str | None) -> State:
    step = TABLE.step(state.phase, event, reason, state.reason)
    return replace(state, phase=step.phase, reason=step.reason)


@dataclass
class Run:
    state: State = field(default_factory=State)
    steps: list[Phase] = field(default_factory=list)


def _steps(stop_after: int | None = None, stop: threading.Event | None = None):
    def step(run: Run):
        run.steps.append(run.state.phase)
        if stop is not None and len(run.steps) == stop_after:
            stop.set()
        return {Phase.A: (Event.GO, "went"), Phase.B: (Event.FINISH, "finished")}[run.state.phase]
    return {Phase.A: step, Phase.B: step}


def test_runs_each_phase_once_to_the_terminal_phase_and_notes_every_state() -> None:
    run, noted, entered, recorded = Run(), [], [], []

    class Record:
        def event(self, phase: str, reason: str) -> None:
            recorded.append((phase, reason))

    note = Transitions("test", recorder=Record(), on_event=lambda phase, reason: noted.append((phase, reason)))
    run_machine(run, _steps(), advance=advance, stop=threading.Event(), stop_event=Event.STOP, note=note,
                entered=lambda r: entered.append(r.state.phase))
    assert run.steps == [Phase.A, Phase.B] and run.state.phase is Phase.DONE
    assert noted == recorded == [("a", ""), ("b", "went"), ("done", "finished")]
    assert entered == [Phase.B, Phase.DONE]


def test_the_operator_stop_is_taken_before_the_next_step() -> None:
    run, stop = Run(), threading.Event()
    run_machine(run, _steps(stop_after=1, stop=stop), advance=advance, stop=stop, stop_event=Event.STOP,
                note=lambda state: None)
    assert run.steps == [Phase.A] and run.state == State(Phase.INTERRUPTED, "stopped by the operator")
