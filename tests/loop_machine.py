"""A small loop machine for the loop kernel's tests: two working phases, a done, a fault and a stop."""

from __future__ import annotations

import enum

from wavestack.loop import StateTable


class Phase(enum.Enum):
    A = "a"
    B = "b"
    DONE = "done"
    FAULTED = "faulted"
    INTERRUPTED = "interrupted"


class Event(enum.Enum):
    GO = "go"
    FINISH = "finish"
    FAULT = "fault"
    STOP = "stop"


TERMINAL = {Phase.DONE, Phase.FAULTED, Phase.INTERRUPTED}
TABLE = StateTable.build({(Phase.A, Event.GO): Phase.B, (Phase.B, Event.FINISH): Phase.DONE}, phases=Phase,
                         terminal=TERMINAL, faulted=Phase.FAULTED, interrupted=Phase.INTERRUPTED, fault=Event.FAULT,
                         stop=Event.STOP)
