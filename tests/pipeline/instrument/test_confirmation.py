"""Aperture confirmation: every phase against every event, through the pure transition function."""

from __future__ import annotations

import itertools

import pytest

from wavestack.pipeline.instrument import (
    ApertureAction,
    ApertureEvent,
    AperturePhase,
    ApertureState,
    Detection,
    confirm,
)
from wavestack.pipeline.instrument import IMPOSSIBLE, TRANSITIONS

# Stand-ins: the transition function only moves apertures and watches between fields.
OLD, CANDIDATE, FOUND = object(), object(), object()
OLD_WATCH, FOUND_WATCH = object(), object()

STATES = {
    AperturePhase.NONE: ApertureState(),
    AperturePhase.HELD: ApertureState(AperturePhase.HELD, OLD, None, OLD_WATCH),
    AperturePhase.PENDING: ApertureState(AperturePhase.PENDING, OLD, CANDIDATE, OLD_WATCH),
}

# (phase, event) -> (next phase, action, current, pending, watch) of the state after the set
EXPECTED = {
    (AperturePhase.NONE, ApertureEvent.NEW): (AperturePhase.HELD, ApertureAction.ADOPT, FOUND, None, FOUND_WATCH),
    (AperturePhase.NONE, ApertureEvent.FAILED): (AperturePhase.NONE, ApertureAction.FORGET, None, None, None),
    (AperturePhase.HELD, ApertureEvent.QUIET): (AperturePhase.HELD, ApertureAction.KEEP, OLD, None, OLD_WATCH),
    (AperturePhase.HELD, ApertureEvent.SAME): (AperturePhase.HELD, ApertureAction.KEEP, OLD, None, FOUND_WATCH),
    (AperturePhase.HELD, ApertureEvent.NEW):
        (AperturePhase.PENDING, ApertureAction.CONFIRMING, OLD, FOUND, OLD_WATCH),
    (AperturePhase.HELD, ApertureEvent.FAILED): (AperturePhase.NONE, ApertureAction.FORGET, None, None, None),
    (AperturePhase.PENDING, ApertureEvent.QUIET): (AperturePhase.HELD, ApertureAction.KEEP, OLD, None, OLD_WATCH),
    (AperturePhase.PENDING, ApertureEvent.SAME): (AperturePhase.HELD, ApertureAction.KEEP, OLD, None, FOUND_WATCH),
    (AperturePhase.PENDING, ApertureEvent.NEW):
        (AperturePhase.PENDING, ApertureAction.CONFIRMING, OLD, FOUND, OLD_WATCH),
    (AperturePhase.PENDING, ApertureEvent.AS_PENDING):
        (AperturePhase.HELD, ApertureAction.ADOPT, FOUND, None, FOUND_WATCH),
    (AperturePhase.PENDING, ApertureEvent.FAILED): (AperturePhase.NONE, ApertureAction.FORGET, None, None, None),
}

PAIRS = list(itertools.product(AperturePhase, ApertureEvent))
DETECTED = {ApertureEvent.SAME, ApertureEvent.NEW, ApertureEvent.AS_PENDING}


def test_the_table_covers_every_pair_exactly_once() -> None:
    assert set(TRANSITIONS) | set(IMPOSSIBLE) == set(PAIRS)
    assert not set(TRANSITIONS) & set(IMPOSSIBLE)
    assert set(EXPECTED) == set(TRANSITIONS)


@pytest.mark.parametrize(("phase", "event"), PAIRS, ids=[f"{p.value}-{e.value}" for p, e in PAIRS])
def test_every_phase_and_event(phase: AperturePhase, event: ApertureEvent) -> None:
    state = STATES[phase]
    detection = Detection(FOUND, FOUND_WATCH) if event in DETECTED else None  # type: ignore[arg-type]
    if (phase, event) in IMPOSSIBLE:
        with pytest.raises(ValueError, match="cannot happen"):
            confirm(state, event, detection)
        return
    after, action = confirm(state, event, detection)
    next_phase, expected_action, current, pending, watch = EXPECTED[(phase, event)]
    assert (after.phase, action) == (next_phase, expected_action)
    assert after.current is current and after.pending is pending and after.watch is watch
    assert state == STATES[phase] and state.current is STATES[phase].current  # the old value is untouched


@pytest.mark.parametrize("event", sorted(DETECTED, key=lambda e: e.value))
def test_a_detection_event_needs_its_detection(event: ApertureEvent) -> None:
    with pytest.raises(ValueError, match="needs the detection"):
        confirm(STATES[AperturePhase.PENDING], event)


def test_a_change_is_adopted_only_when_the_next_set_confirms_it() -> None:
    state, action = confirm(ApertureState(), ApertureEvent.NEW, Detection(OLD, OLD_WATCH))  # type: ignore[arg-type]
    assert action is ApertureAction.ADOPT
    state, action = confirm(state, ApertureEvent.NEW, Detection(FOUND, FOUND_WATCH))  # type: ignore[arg-type]
    assert action is ApertureAction.CONFIRMING and state.current is OLD and state.pending is FOUND
    state, action = confirm(state, ApertureEvent.AS_PENDING, Detection(FOUND, FOUND_WATCH))  # type: ignore[arg-type]
    assert action is ApertureAction.ADOPT and state.current is FOUND and state.phase is AperturePhase.HELD
