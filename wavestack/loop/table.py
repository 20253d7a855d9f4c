"""A closed loop's life as data: the transition table, its terminal phases, and one pure step.

Every loop (a polishing campaign, an alignment) is a machine of the same kind: working phases
that each do one piece of work and name what happened as an event, terminal phases that say why
the loop stopped and never leave, and two events every working phase expects: a fault (ends in
the faulted phase) and the operator's stop (ends in the interrupted phase). An event a phase does
not expect is a bug in the caller or a device that reports nonsense; the safe reading is to stop,
so it ends the loop in the faulted phase, naming both. :class:`StateTable` holds one loop's
machine; :meth:`StateTable.step` applies it, and the loop's own ``advance`` adds its counters
(runs done, iterations done) on top.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Generic, TypeVar

__all__ = ["Step", "StateTable"]

P = TypeVar("P", bound=enum.Enum)
E = TypeVar("E", bound=enum.Enum)


@dataclass(frozen=True)
class Step(Generic[P]):
    """Where one event leads.

    Attributes
    ----------
    phase : enum member
        The next phase (the same terminal phase when the loop had stopped).
    reason : str or None
        The reason the new state keeps: the event's, or for a terminal phase the last one known.
    expected : bool
        False for an event the phase does not expect (the loop then faults) or a loop that had
        stopped (nothing changes); the caller's counters move only on an expected event.
    """

    phase: P
    reason: str | None
    expected: bool


@dataclass(frozen=True)
class StateTable(Generic[P, E]):
    """One loop's machine (module notes).

    Build it with :meth:`build` from the expected transitions of the working phases; the fault and
    stop rows of every working phase are added there.

    Attributes
    ----------
    transitions : mapping (phase, event) -> phase
        Every expected event of every working phase, fault and stop included.
    terminal : frozenset of phases
        Phases the loop never leaves.
    faulted, interrupted : phase
        Where a fault (or an unexpected event) and the operator's stop end.

    Example
    -------
    >>> class Phase(enum.Enum):
    ...     WORKING = "working"; DONE = "done"; FAULTED = "faulted"; INTERRUPTED = "interrupted"
    >>> class Event(enum.Enum):
    ...     FINISHED = "finished"; FAULT = "fault"; STOP = "stop"
    >>> table = StateTable.build({(Phase.WORKING, Event.FINISHED): Phase.DONE}, phases=Phase,
    ...                          terminal={Phase.DONE, Phase.FAULTED, Phase.INTERRUPTED}, faulted=Phase.FAULTED,
    ...                          interrupted=Phase.INTERRUPTED, fault=Event.FAULT, stop=Event.STOP)
    >>> table.step(Phase.WORKING, Event.FINISHED, "all done", None).phase.value
    'done'
    >>> table.step(Phase.DONE, Event.FAULT, "late", "all done")
    Step(phase=<Phase.DONE: 'done'>, reason='all done', expected=False)
    """

    transitions: Mapping[tuple[P, E], P]
    terminal: frozenset[P]
    faulted: P
    interrupted: P

    @classmethod
    def build(cls, expected: Mapping[tuple[P, E], P], *, phases: Iterable[P], terminal: Iterable[P], faulted: P,
              interrupted: P, fault: E, stop: E) -> StateTable[P, E]:
        """The table of ``expected`` plus a fault and a stop row for every working phase.

        Raises
        ------
        ValueError
            A transition out of a terminal phase, or ``faulted``/``interrupted`` not terminal.
        """
        ends = frozenset(terminal)
        if faulted not in ends or interrupted not in ends:
            raise ValueError(f"faulted ({faulted}) and interrupted ({interrupted}) must be terminal phases")
        leaving = [key for key in expected if key[0] in ends]
        if leaving:
            raise ValueError(f"a terminal phase never leaves; got transitions {leaving}")
        working = [phase for phase in phases if phase not in ends]
        rows = {**expected, **{(phase, fault): faulted for phase in working},
                **{(phase, stop): interrupted for phase in working}}
        return cls(rows, ends, faulted, interrupted)

    def step(self, phase: P, event: E, reason: str | None, kept: str | None) -> Step[P]:
        """Where ``event`` leads from ``phase`` (pure; module notes).

        Parameters
        ----------
        phase, event
        reason : str or None
            Why (faults, refusals, stops).
        kept : str or None
            The reason the state holds now (a terminal phase keeps it).
        """
        if phase in self.terminal:
            return Step(phase, kept, False)
        following = self.transitions.get((phase, event))
        if following is None:
            why = f"unexpected event {event.value!r} while {phase.value}" + (f" ({reason})" if reason else "")
            return Step(self.faulted, why, False)
        return Step(following, reason if reason is not None else (kept if following in self.terminal else None), True)
