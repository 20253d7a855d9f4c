"""Aperture confirmation as data: a changed aperture is adopted only when the next set confirms it.

A phase-shifted set whose frames straddle the moment the optic moved shows a mixture of both
apertures (measured on the simulated station: one component with three holes), which must not cost
a fitter build; the straddling set itself is reported invalid. The rule is an explicit state value
(:class:`ApertureState`) and a pure transition function (:func:`confirm`) over the table
:data:`TRANSITIONS`, in the manner of h11's ``_state.py``: the processor classifies what a set
shows into an :class:`ApertureEvent`, the table says what happens.

The table knows nothing of fringes: it only moves the aperture in use, the pending one and the
watch between fields. Every instrument's processor uses it: the interferometers' pixel apertures,
and a Shack-Hartmann sensor's set of lit lenslets (an :class:`~wavestack.pipeline.Aperture` on the
lenslet grid, with or without a watch).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from ..aperture import Aperture, ApertureWatch


class AperturePhase(enum.Enum):
    """Where the confirmation stands."""

    NONE = "none"  #: no aperture (at start, or after a detection failed)
    HELD = "held"  #: an aperture in use, nothing pending
    PENDING = "pending"  #: an aperture in use and a different one waiting for the next set to confirm it


class ApertureEvent(enum.Enum):
    """What one set shows, as the processor classified it."""

    QUIET = "quiet"  #: the cheap per-frame watch saw no change (no detection ran)
    SAME = "same"  #: a full detection found the aperture in use (the watch saw noise)
    NEW = "new"  #: a full detection found an aperture unlike the one in use and unlike the pending one
    AS_PENDING = "as-pending"  #: a full detection found the pending aperture again: confirmed
    FAILED = "failed"  #: the detection failed (empty or unsupported aperture, no signal)


class ApertureAction(enum.Enum):
    """What the processor does with the set."""

    KEEP = "keep"  #: go on with the aperture in use
    ADOPT = "adopt"  #: start the detected aperture (a new fitter); this set is valid and "changed"
    CONFIRMING = "confirming"  #: report this set invalid; the next set must confirm the change
    FORGET = "forget"  #: report this set invalid and forget the aperture


#: (phase, event) -> (next phase, action). Pairs absent here cannot happen (see :data:`IMPOSSIBLE`).
TRANSITIONS: Final[Mapping[tuple[AperturePhase, ApertureEvent], tuple[AperturePhase, ApertureAction]]] = MappingProxyType({
    (AperturePhase.NONE, ApertureEvent.NEW): (AperturePhase.HELD, ApertureAction.ADOPT),
    (AperturePhase.NONE, ApertureEvent.FAILED): (AperturePhase.NONE, ApertureAction.FORGET),
    (AperturePhase.HELD, ApertureEvent.QUIET): (AperturePhase.HELD, ApertureAction.KEEP),
    (AperturePhase.HELD, ApertureEvent.SAME): (AperturePhase.HELD, ApertureAction.KEEP),
    (AperturePhase.HELD, ApertureEvent.NEW): (AperturePhase.PENDING, ApertureAction.CONFIRMING),
    (AperturePhase.HELD, ApertureEvent.FAILED): (AperturePhase.NONE, ApertureAction.FORGET),
    (AperturePhase.PENDING, ApertureEvent.QUIET): (AperturePhase.HELD, ApertureAction.KEEP),
    (AperturePhase.PENDING, ApertureEvent.SAME): (AperturePhase.HELD, ApertureAction.KEEP),
    (AperturePhase.PENDING, ApertureEvent.NEW): (AperturePhase.PENDING, ApertureAction.CONFIRMING),
    (AperturePhase.PENDING, ApertureEvent.AS_PENDING): (AperturePhase.HELD, ApertureAction.ADOPT),
    (AperturePhase.PENDING, ApertureEvent.FAILED): (AperturePhase.NONE, ApertureAction.FORGET),
})

#: Pairs that cannot occur: no watch without an aperture, nothing to confirm without a pending one.
IMPOSSIBLE: Final = frozenset({
    (AperturePhase.NONE, ApertureEvent.QUIET), (AperturePhase.NONE, ApertureEvent.SAME),
    (AperturePhase.NONE, ApertureEvent.AS_PENDING), (AperturePhase.HELD, ApertureEvent.AS_PENDING),
})


@dataclass(frozen=True, eq=False)
class Detection:
    """A full detection's outcome: the aperture as the fit uses it and its per-frame watch (None: none)."""

    aperture: Aperture
    watch: ApertureWatch | None


@dataclass(frozen=True, eq=False)
class ApertureState:
    """The aperture in use, the one waiting for confirmation, and the watch that checks each frame."""

    phase: AperturePhase = AperturePhase.NONE
    current: Aperture | None = None
    pending: Aperture | None = None
    watch: ApertureWatch | None = None


def confirm(state: ApertureState, event: ApertureEvent,
            detection: Detection | None = None) -> tuple[ApertureState, ApertureAction]:
    """The next state and the action for one set (pure: the table :data:`TRANSITIONS` decides).

    Parameters
    ----------
    state : ApertureState
    event : ApertureEvent
        What the set shows.
    detection : Detection, optional
        Required for ``SAME``, ``NEW`` and ``AS_PENDING`` (a full detection ran).

    Returns
    -------
    (ApertureState, ApertureAction)
        ``SAME`` keeps the aperture but takes the fresh watch; ``NEW`` keeps the old watch, so the
        next set is checked in full again; ``ADOPT`` takes the detected aperture and its watch.

    Raises
    ------
    ValueError
        An impossible pair (:data:`IMPOSSIBLE`), or a detection event without its detection.
    """
    key = (state.phase, event)
    if key not in TRANSITIONS:
        raise ValueError(f"aperture confirmation: {event.value!r} cannot happen in phase {state.phase.value!r}")
    phase, action = TRANSITIONS[key]
    if event in (ApertureEvent.QUIET, ApertureEvent.FAILED):
        if event is ApertureEvent.FAILED:
            return ApertureState(), action
        return ApertureState(phase, state.current, None, state.watch), action
    if detection is None:
        raise ValueError(f"aperture confirmation: event {event.value!r} needs the detection")
    if action is ApertureAction.ADOPT:
        return ApertureState(phase, detection.aperture, None, detection.watch), action
    if action is ApertureAction.CONFIRMING:
        return ApertureState(phase, state.current, detection.aperture, state.watch), action
    return ApertureState(phase, state.current, None, detection.watch), action  # SAME: the watch saw noise
