"""The alignment loop's life as data: a frozen state, the events, and one pure transition.

One iteration is: for each field point, move the field stage, measure; then estimate the
misalignment, move the hexapod, wait on target, verify the position read back; then the next
iteration. The loop stops at the target RMS at every field point, after ``max_iterations``
corrections, when the wavefront stops improving, on any fault, or when the operator stops it.
Each stop is a terminal phase naming why, and a terminal phase never leaves (every later event is
ignored), so nothing moves after a stop. :data:`TABLE` (the loop kernel's
:class:`~wavestack.loop.StateTable`) is the whole machine; :func:`advance` applies it and counts
field points and corrections. An event a phase does not expect ends the loop in
:attr:`AlignPhase.FAULTED`, naming both (the kernel's rule).

Only :attr:`AlignEvent.MEASURED` leaves measuring for the next field point or the check, and only
a check that asks for more work leads to estimating, so a hexapod move is never computed from a
measurement the loop did not trust (:attr:`AlignEvent.UNTRUSTED` faults). The caller halts the
platform on entering :attr:`AlignPhase.FAULTED` (``halt_on_entry``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace
from typing import Final

from wavestack.loop import StateTable

__all__ = ["AlignEvent", "AlignPhase", "AlignState", "TABLE", "TERMINAL_PHASES", "TRANSITIONS", "advance",
           "judge_iteration"]


class AlignPhase(enum.Enum):
    """Where the loop is."""

    MOVING_FIELD = "moving-field"      # the field stage to the next field point
    MEASURING = "measuring"            # averaging valid results at this field point
    CHECKING = "checking"              # every field point measured: target, budget, improvement
    ESTIMATING = "estimating"          # the misalignment from the sensitivity matrix
    MOVING_HEXAPOD = "moving-hexapod"  # the correction sent (after the limits and the max step)
    WAITING = "waiting"                # wait on target
    VERIFYING = "verifying"            # the position read back against the move sent
    TARGET_MET = "target-met"          # terminal: RMS <= target at every field point
    MAX_ITERATIONS = "max-iterations"  # terminal: the correction budget is spent
    NOT_IMPROVING = "not-improving"    # terminal: the worst field RMS did not decrease
    FAULTED = "faulted"                # terminal: a fault (the reason says which); the platform halted
    INTERRUPTED = "interrupted"        # terminal: the operator stopped the loop


class AlignEvent(enum.Enum):
    """What happened."""

    FIELD_REACHED = "field-reached"    # the field stage is on target at the next point
    MEASURED = "measured"              # a trusted measurement, more field points to go
    ALL_MEASURED = "all-measured"      # a trusted measurement of the last field point
    UNTRUSTED = "untrusted"            # a measurement refused (invalid, stale, camera lost)
    AT_TARGET = "at-target"
    ITERATIONS_EXHAUSTED = "iterations-exhausted"
    NOT_IMPROVED = "not-improved"
    NEEDS_WORK = "needs-work"
    ESTIMATED = "estimated"            # a correction within the limits
    MOVE_SENT = "move-sent"
    ON_TARGET = "on-target"
    VERIFIED = "verified"              # read-back within tolerance: the next iteration begins
    FAULT = "fault"
    STOP = "stop"


TERMINAL_PHASES: Final = frozenset({AlignPhase.TARGET_MET, AlignPhase.MAX_ITERATIONS, AlignPhase.NOT_IMPROVING,
                                    AlignPhase.FAULTED, AlignPhase.INTERRUPTED})

_P, _E = AlignPhase, AlignEvent
#: (phase, event) -> next phase for every expected event; FAULT and STOP everywhere non-terminal.
TABLE: Final = StateTable.build({
    (_P.MOVING_FIELD, _E.FIELD_REACHED): _P.MEASURING,
    (_P.MEASURING, _E.MEASURED): _P.MOVING_FIELD,
    (_P.MEASURING, _E.ALL_MEASURED): _P.CHECKING,
    (_P.MEASURING, _E.UNTRUSTED): _P.FAULTED,
    (_P.CHECKING, _E.AT_TARGET): _P.TARGET_MET,
    (_P.CHECKING, _E.ITERATIONS_EXHAUSTED): _P.MAX_ITERATIONS,
    (_P.CHECKING, _E.NOT_IMPROVED): _P.NOT_IMPROVING,
    (_P.CHECKING, _E.NEEDS_WORK): _P.ESTIMATING,
    (_P.ESTIMATING, _E.ESTIMATED): _P.MOVING_HEXAPOD,
    (_P.MOVING_HEXAPOD, _E.MOVE_SENT): _P.WAITING,
    (_P.WAITING, _E.ON_TARGET): _P.VERIFYING,
    (_P.VERIFYING, _E.VERIFIED): _P.MOVING_FIELD,
}, phases=_P, terminal=TERMINAL_PHASES, faulted=_P.FAULTED, interrupted=_P.INTERRUPTED, fault=_E.FAULT, stop=_E.STOP)
TRANSITIONS: Final = TABLE.transitions


@dataclass(frozen=True)
class AlignState:
    """The loop's state.

    Attributes
    ----------
    phase : AlignPhase
    iterations_done : int
        Corrections applied and verified.
    field_index : int
        The field point being moved to or measured (0 after a verified correction).
    reason : str or None
        Why the loop stopped (terminal phases), or the last transition's reason.

    Example
    -------
    >>> advance(AlignState(), AlignEvent.FIELD_REACHED).phase.value
    'measuring'
    """

    phase: AlignPhase = AlignPhase.MOVING_FIELD
    iterations_done: int = 0
    field_index: int = 0
    reason: str | None = None

    @property
    def terminal(self) -> bool:
        """True once the loop has stopped (it never starts again)."""
        return self.phase in TERMINAL_PHASES

    @property
    def halt_on_entry(self) -> bool:
        """True when the caller must halt the hexapod now (a fault or a stop)."""
        return self.phase in (AlignPhase.FAULTED, AlignPhase.INTERRUPTED)


def advance(state: AlignState, event: AlignEvent, reason: str | None = None) -> AlignState:
    """The state after ``event`` (pure).

    ``field_index`` grows on MEASURED and goes back to 0 on VERIFIED; ``iterations_done`` grows on
    VERIFIED. A terminal state is returned unchanged; an unexpected event faults.

    Example
    -------
    >>> s = advance(AlignState(AlignPhase.VERIFYING, 0, 4), AlignEvent.VERIFIED)
    >>> (s.phase.value, s.iterations_done, s.field_index)
    ('moving-field', 1, 0)
    """
    step = TABLE.step(state.phase, event, reason, state.reason)
    if not step.expected:
        return replace(state, phase=step.phase, reason=step.reason)
    index, iterations = state.field_index, state.iterations_done
    if event is AlignEvent.MEASURED:
        index += 1
    elif event is AlignEvent.VERIFIED:
        index, iterations = 0, iterations + 1
    return AlignState(step.phase, iterations, index, step.reason)


def judge_iteration(rms_waves: tuple[float, ...], previous_worst: float | None, iterations_done: int, *,
                    target_rms_waves: float, max_iterations: int,
                    min_improvement: float = 0.0) -> tuple[AlignEvent, str]:
    """What a full set of field measurements means (pure): the check's event and its reason.

    In this order: any RMS not finite -> FAULT; every field point at or below the target ->
    AT_TARGET; the worst field RMS not below ``previous_worst * (1 - min_improvement)`` ->
    NOT_IMPROVED; ``iterations_done >= max_iterations`` -> ITERATIONS_EXHAUSTED; else NEEDS_WORK.

    Parameters
    ----------
    rms_waves : tuple of float
        RMS wavefront error per field point, waves.
    previous_worst : float or None
        The worst field RMS before the last correction (None before the first).

    Example
    -------
    >>> judge_iteration((0.05, 0.06), 0.3, 2, target_rms_waves=1 / 14, max_iterations=5)[0].value
    'at-target'
    """
    if not rms_waves or not all(r == r and r != float("inf") for r in rms_waves):
        return AlignEvent.FAULT, f"field RMS not finite: {rms_waves}"
    worst = max(rms_waves)
    if worst <= target_rms_waves:
        return AlignEvent.AT_TARGET, f"worst field RMS {worst:.4f} waves <= target {target_rms_waves:.4f}"
    if previous_worst is not None and not worst < previous_worst * (1.0 - min_improvement):
        return AlignEvent.NOT_IMPROVED, (f"correction {iterations_done} did not improve the worst field RMS: "
                                         f"{previous_worst:.4f} -> {worst:.4f} waves")
    if iterations_done >= max_iterations:
        return AlignEvent.ITERATIONS_EXHAUSTED, (f"{iterations_done} correction(s) done (max {max_iterations}); "
                                                 f"worst field RMS {worst:.4f} waves")
    return AlignEvent.NEEDS_WORK, f"worst field RMS {worst:.4f} waves > target {target_rms_waves:.4f}"
