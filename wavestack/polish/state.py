"""The polishing loop's life as data: a frozen state, the events, and one pure transition.

One run of the loop is measure -> check -> solve -> program -> hand-off -> wait -> measure. The
loop stops at the target RMS, at the floor (the best job within the machine's limits and its model
errors would not lower the RMS by more than the tolerance), after ``max_runs`` runs, when a run
fails to improve the RMS, on any fault, or when the operator stops it; each stop is a terminal phase that names why, and a terminal
phase never leaves (every later event is ignored), so nothing is sent after a stop. The table
:data:`TRANSITIONS` is the whole machine; :func:`advance` applies it. An event a phase does not
expect (a bug in the caller, or a device that reports nonsense) ends the loop in
:attr:`LoopPhase.FAULTED`, naming both, rather than guessing: the safe reading of the unexpected.

Only :attr:`LoopEvent.MEASURED` leads from measuring to checking, and only a check that asks for
more work leads to solving, so a job is never built on a measurement the loop did not trust
(:attr:`LoopEvent.UNTRUSTED` faults). A job handed off is never sent again: the only way out of
:attr:`LoopPhase.POLISHING` is the machine's done (measure again) or a fault.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace
from typing import Final

from wavestack.pipeline.surface import SpecVerdict

__all__ = ["LoopEvent", "LoopPhase", "LoopState", "TERMINAL_PHASES", "TRANSITIONS", "advance", "judge_job", "judge_measurement"]


class LoopPhase(enum.Enum):
    """Where the loop is."""

    MEASURING = "measuring"          # averaging live results into a surface map
    CHECKING = "checking"            # the trusted measurement against the target, the last run, the run count
    SOLVING = "solving"              # the dwell-time map
    PROGRAMMING = "programming"      # the machine program, checked against the limits
    HANDING_OFF = "handing-off"      # the job file written, announced, started
    POLISHING = "polishing"          # waiting for the machine's done
    TARGET_MET = "target-met"        # terminal: RMS at or below the target
    MAX_RUNS = "max-runs"            # terminal: the run budget is spent
    NOT_IMPROVING = "not-improving"  # terminal: the last run did not lower the RMS, or no job would
    FLOOR_REACHED = "floor-reached"  # terminal: the RMS is within the tolerance of the floor of the best job
    FAULTED = "faulted"              # terminal: a fault (the reason says which)
    INTERRUPTED = "interrupted"      # terminal: the operator stopped the loop


class LoopEvent(enum.Enum):
    """What happened."""

    MEASURED = "measured"            # a trusted measurement
    UNTRUSTED = "untrusted"          # a measurement refused (invalid, stale, aperture changed, noisy)
    AT_TARGET = "at-target"
    RUNS_EXHAUSTED = "runs-exhausted"
    NOT_IMPROVED = "not-improved"
    NEEDS_WORK = "needs-work"
    SOLVED = "solved"
    NO_GAIN = "no-gain"              # the best job within the limits is not predicted to lower the RMS
    AT_FLOOR = "at-floor"            # the RMS is within the tolerance of the best job's floor
    PROGRAMMED = "programmed"
    HANDED_OFF = "handed-off"        # the machine accepted and started the job
    MACHINE_DONE = "machine-done"    # the machine finished the job
    FAULT = "fault"                  # anything that went wrong (the reason says what)
    STOP = "stop"                    # the operator (Ctrl-C, SIGTERM)


#: Phases the loop never leaves.
TERMINAL_PHASES: Final = frozenset({LoopPhase.TARGET_MET, LoopPhase.MAX_RUNS, LoopPhase.NOT_IMPROVING,
                                    LoopPhase.FLOOR_REACHED, LoopPhase.FAULTED, LoopPhase.INTERRUPTED})

_P, _E = LoopPhase, LoopEvent
#: (phase, event) -> next phase, for every expected event of every working phase. FAULT and STOP
#: are expected everywhere; anything else not listed faults (module notes).
TRANSITIONS: Final[dict[tuple[LoopPhase, LoopEvent], LoopPhase]] = {
    (_P.MEASURING, _E.MEASURED): _P.CHECKING,
    (_P.MEASURING, _E.UNTRUSTED): _P.FAULTED,
    (_P.CHECKING, _E.AT_TARGET): _P.TARGET_MET,
    (_P.CHECKING, _E.RUNS_EXHAUSTED): _P.MAX_RUNS,
    (_P.CHECKING, _E.NOT_IMPROVED): _P.NOT_IMPROVING,
    (_P.CHECKING, _E.NEEDS_WORK): _P.SOLVING,
    (_P.SOLVING, _E.SOLVED): _P.PROGRAMMING,
    (_P.SOLVING, _E.NO_GAIN): _P.NOT_IMPROVING,
    (_P.SOLVING, _E.AT_FLOOR): _P.FLOOR_REACHED,
    (_P.PROGRAMMING, _E.PROGRAMMED): _P.HANDING_OFF,
    (_P.HANDING_OFF, _E.HANDED_OFF): _P.POLISHING,
    (_P.POLISHING, _E.MACHINE_DONE): _P.MEASURING,
    **{(phase, _E.FAULT): _P.FAULTED for phase in _P if phase not in TERMINAL_PHASES},
    **{(phase, _E.STOP): _P.INTERRUPTED for phase in _P if phase not in TERMINAL_PHASES},
}


@dataclass(frozen=True)
class LoopState:
    """The loop's state.

    Attributes
    ----------
    phase : LoopPhase
    runs_done : int
        Jobs the machine finished (a run counts once its job is done).
    reason : str or None
        Why the loop stopped (terminal phases), or the last fault.

    Example
    -------
    >>> state = advance(LoopState(), LoopEvent.MEASURED)
    >>> state.phase.value
    'checking'
    """

    phase: LoopPhase = LoopPhase.MEASURING
    runs_done: int = 0
    reason: str | None = None

    @property
    def terminal(self) -> bool:
        """True once the loop has stopped (it never starts again)."""
        return self.phase in TERMINAL_PHASES


def advance(state: LoopState, event: LoopEvent, reason: str | None = None) -> LoopState:
    """The state after ``event`` (pure).

    Parameters
    ----------
    state : LoopState
    event : LoopEvent
    reason : str, optional
        Why (faults, refusals, stops); kept on the new state.

    Returns
    -------
    LoopState
        The same state for a terminal one; :attr:`LoopPhase.FAULTED` for an event the phase does
        not expect; ``runs_done`` grows by one on :attr:`LoopEvent.MACHINE_DONE`.

    Example
    -------
    >>> advance(LoopState(LoopPhase.POLISHING), LoopEvent.MACHINE_DONE).runs_done
    1
    """
    if state.terminal:
        return state
    following = TRANSITIONS.get((state.phase, event))
    if following is None:
        return replace(state, phase=LoopPhase.FAULTED,
                       reason=f"unexpected event {event.value!r} while {state.phase.value}"
                              + (f" ({reason})" if reason else ""))
    runs = state.runs_done + (event is LoopEvent.MACHINE_DONE)
    kept = reason if reason is not None else (state.reason if following in TERMINAL_PHASES else None)
    return LoopState(following, runs, kept)


def judge_measurement(rms_nm: float, previous_rms_nm: float | None, runs_done: int, *, target_rms_nm: float,
                      max_runs: int, min_improvement: float = 0.0,
                      verdict: SpecVerdict | None = None) -> tuple[LoopEvent, str]:
    """What a trusted measurement means for the loop (pure): the check step's event and its reason.

    In this order: at or below the target -> AT_TARGET; the last run did not lower the RMS by at
    least the fraction ``min_improvement`` -> NOT_IMPROVED; ``runs_done >= max_runs`` ->
    RUNS_EXHAUSTED; else NEEDS_WORK. The target is checked first so a last run that reaches it
    ends as a success, not as a spent budget. With the drawing's ``verdict`` the target is the
    drawing: AT_TARGET when every toleranced quantity passes (whatever the RMS), and every other
    reason names the limiting quantity.

    Parameters
    ----------
    rms_nm : float
        This measurement's surface RMS, nm.
    previous_rms_nm : float or None
        The measurement before the last run (None before the first run).
    runs_done : int
    target_rms_nm : float
    max_runs : int
    min_improvement : float
        Fraction of the previous RMS a run must remove at least (0: any decrease counts).
    verdict : SpecVerdict, optional
        This measurement against the drawing's tolerance (``polish --spec``).

    Returns
    -------
    (LoopEvent, str)

    Example
    -------
    >>> judge_measurement(4.0, 12.0, 1, target_rms_nm=5.0, max_runs=4)[0].value
    'at-target'
    """
    if not rms_nm == rms_nm:  # NaN: never a reason to polish
        return LoopEvent.FAULT, "measured RMS is not a number"
    drawing = "" if verdict is None else f"; drawing {verdict.summary()}"
    if (verdict.passed if verdict is not None else rms_nm <= target_rms_nm):
        met = verdict.summary() if verdict is not None else f"RMS {rms_nm:.2f} nm <= target {target_rms_nm:g} nm"
        return LoopEvent.AT_TARGET, met
    if previous_rms_nm is not None and not rms_nm < previous_rms_nm * (1.0 - min_improvement):
        return LoopEvent.NOT_IMPROVED, (f"run {runs_done} did not improve the RMS: {previous_rms_nm:.2f} -> "
                                        f"{rms_nm:.2f} nm{drawing}")
    if runs_done >= max_runs:
        return LoopEvent.RUNS_EXHAUSTED, (f"{runs_done} run(s) done (max_runs = {max_runs}); RMS {rms_nm:.2f} nm"
                                          f"{drawing}")
    if verdict is not None:
        return LoopEvent.NEEDS_WORK, f"RMS {rms_nm:.2f} nm; drawing {verdict.summary()}"
    return LoopEvent.NEEDS_WORK, f"RMS {rms_nm:.2f} nm > target {target_rms_nm:g} nm"


def judge_job(rms_nm: float, predicted_rms_nm: float, floor_nm: float | None, *, floor_tolerance: float,
              min_improvement: float = 0.0) -> LoopEvent:
    """What the best job within the limits means for the loop (pure): the solve step's event.

    In this order: the measured RMS is within ``floor_tolerance`` of the job's floor (what the
    tool cannot remove within the job's limits and the model's errors, :mod:`~wavestack.polish.floor`)
    -> AT_FLOOR; the job is not predicted to lower the RMS by at least the fraction
    ``min_improvement`` -> NO_GAIN; else SOLVED. The floor is checked first: at the floor a
    job may still be predicted to help, but what it would remove is below what the machine's
    errors put back.

    Parameters
    ----------
    rms_nm : float
        The measured surface RMS, nm.
    predicted_rms_nm : float
        The job's predicted residual RMS, nm.
    floor_nm : float or None
        The job's floor, nm (None: no floor estimated, never AT_FLOOR).
    floor_tolerance : float
        Fraction above the floor that still counts as at the floor.
    min_improvement : float
        Fraction of the measured RMS the job must be predicted to remove at least.

    Example
    -------
    >>> judge_job(6.2, 5.9, 5.8, floor_tolerance=0.1).value
    'at-floor'
    """
    if floor_nm is not None and rms_nm <= floor_nm * (1.0 + floor_tolerance):
        return LoopEvent.AT_FLOOR
    if not predicted_rms_nm < rms_nm * (1.0 - min_improvement):
        return LoopEvent.NO_GAIN
    return LoopEvent.SOLVED
