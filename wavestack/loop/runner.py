"""Run a loop's machine to a terminal phase: each phase does its one piece of work and names what happened.

:func:`run_machine` is the one runner of every closed loop: while the state is not terminal it
asks the step of the current phase for an event and a reason (or, once the operator's stop is
set, takes the stop event), advances the state with the loop's pure ``advance``, lets the loop
act on the phase it entered (the alignment halts its hexapod on a fault or a stop) and notes the
transition. :class:`Transitions` is that note: the log line, the campaign record's event, and the
caller's ``on_event(phase, reason)`` (the terminal printer, the web view).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from typing import Any, Protocol, TypeVar

__all__ = ["LoopContext", "Transitions", "run_machine"]

logger = logging.getLogger(__name__)

C = TypeVar("C", bound="LoopContext")


class LoopState(Protocol):
    """What the runner reads of a loop's state."""

    @property
    def phase(self) -> Any: ...

    @property
    def reason(self) -> str | None: ...

    @property
    def terminal(self) -> bool: ...


class EventRecord(Protocol):
    """Where transitions are recorded (a loop's campaign record)."""

    def event(self, phase: str, reason: str) -> object: ...


class LoopContext(Protocol):
    """The loop's run in flight: its state, replaced on every transition."""

    state: Any


class Transitions:
    """Notes every state a loop enters: a log line, the campaign record's event, ``on_event``.

    Parameters
    ----------
    name : str
        The loop's name in the log (``"polish"``, ``"align"``).
    recorder : EventRecord, optional
        A campaign record (its ``event(phase, reason)``).
    on_event : callable, optional
        ``on_event(phase, reason)``.

    Example
    -------
    >>> seen = []
    >>> note = Transitions("demo", on_event=lambda phase, reason: seen.append((phase, reason)))
    >>> class State:
    ...     phase, reason = type("P", (), {"value": "measuring"})(), "start"
    >>> note(State()); seen
    [('measuring', 'start')]
    """

    def __init__(self, name: str, *, recorder: EventRecord | None = None,
                 on_event: Callable[[str, str], None] | None = None) -> None:
        self._name, self._recorder, self._on_event = name, recorder, on_event

    def __call__(self, state: LoopState) -> None:
        phase, reason = state.phase.value, state.reason or ""
        logger.info("%s: %s (%s)", self._name, phase, reason)
        if self._recorder is not None:
            self._recorder.event(phase, reason)
        if self._on_event is not None:
            self._on_event(phase, reason)


def run_machine(context: C, steps: Mapping[Any, Callable[[C], tuple[Any, str]]], *,
                advance: Callable[[Any, Any, str], Any], stop: threading.Event, stop_event: Any,
                note: Callable[[Any], None], entered: Callable[[C], None] | None = None) -> None:
    """Drive ``context.state`` to a terminal phase (module notes); returns when it is terminal.

    Parameters
    ----------
    context
        Holds ``state`` (replaced by each transition) and whatever the steps share.
    steps : mapping phase -> callable
        ``step(context) -> (event, reason)`` for every working phase.
    advance : callable
        The loop's pure ``advance(state, event, reason) -> state``.
    stop : threading.Event
        The operator's stop: checked before every step.
    stop_event
        The event a stop is (the table's stop row leads every working phase to ``interrupted``).
    note : callable
        Called with every state the loop enters, the first included (:class:`Transitions`).
    entered : callable, optional
        Called with the context after each transition, before the note (e.g. halt on a fault).
    """
    note(context.state)
    while not context.state.terminal:
        if stop.is_set():
            event, reason = stop_event, "stopped by the operator"
        else:
            event, reason = steps[context.state.phase](context)
        context.state = advance(context.state, event, reason)
        if entered is not None:
            entered(context)
        note(context.state)
