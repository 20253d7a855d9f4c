"""Faults end the alignment in FAULTED with the hexapod halted (#24 received) and no move after the fault.

Every fault is injected through the simulators' own switches (the GCS simulator's ``faults``, the
bench's camera switch), never by patching.
"""

from __future__ import annotations

import threading
from contextlib import ExitStack
from dataclasses import replace

import numpy as np

from wavestack.align import AlignPhase
from wavestack.align.loop import AlignmentLoop, AlignSummary
from wavestack.align.session import AlignSession, open_session, options_of
from wavestack.config.align import load_align_config

CONFIG = load_align_config()


def _run(arm, *, move_timeout_s: float = 30.0) -> tuple[AlignSummary, AlignSession, tuple[str, ...], int]:
    """Run the loop with ``arm(session, phase, reason)`` called on every transition."""
    with ExitStack() as stack:
        session = open_session(CONFIG, stack)
        options = replace(options_of(CONFIG), move_timeout_s=move_timeout_s)
        loop = AlignmentLoop(**session.loop_arguments(), options=options, stop=threading.Event(),
                             on_event=lambda phase, reason: arm(session, phase, reason))
        summary = loop.run()
        commands = session.bench.hexapod.controller.commands
        controller = session.bench.hexapod.controller
        still = controller.pose.values == controller.targets.values  # nothing left to move to
        moves = sum(1 for c in commands if c.startswith("MOV"))
    assert still, "the platform still had a target to move to after the fault"
    return summary, session, commands, moves


def _assert_halted(summary: AlignSummary, commands: tuple[str, ...]) -> None:
    assert summary.state.phase is AlignPhase.FAULTED
    assert summary.halted is True
    last_stop = max(i for i, c in enumerate(commands) if c in ("#24", "\x18"))
    assert not any(c.startswith("MOV") for c in commands[last_stop:])  # nothing moved after the halt


def test_controller_error_on_the_move() -> None:
    def arm(session, phase, reason):
        if phase == "checking" and "all measured" in reason:
            session.bench.hexapod.faults.fail_next(7, command="MOV")
    summary, _, commands, moves = _run(arm)
    _assert_halted(summary, commands)
    assert "hexapod move refused or failed" in (summary.state.reason or "") and moves == 1


def test_stuck_axis_times_out_and_halts() -> None:
    def arm(session, phase, reason):
        if phase == "checking" and "all measured" in reason:
            session.bench.hexapod.faults.stick_axis("Z")
    summary, _, commands, _ = _run(arm, move_timeout_s=1.0)
    _assert_halted(summary, commands)
    assert "not on target" in (summary.state.reason or "")


def test_dropped_connection_reconnects_to_halt() -> None:
    def arm(session, phase, reason):
        if phase == "checking" and "all measured" in reason:
            session.bench.hexapod.faults.drop_connection(command="MOV")
    summary, _, commands, _ = _run(arm)
    _assert_halted(summary, commands)
    assert "hexapod" in (summary.state.reason or "")


def test_camera_lost_during_a_measurement_sends_no_move() -> None:
    def arm(session, phase, reason):
        if phase == "moving-field" and reason == "read-back within tolerance":
            session.bench.lose_camera(1)  # the first measurement after the first correction
    summary, session, commands, moves = _run(arm)
    _assert_halted(summary, commands)
    assert "refused" in (summary.state.reason or "") and "camera lost" in (summary.state.reason or "")
    assert moves == 1 and summary.state.iterations_done == 1  # the correction before, none after


def test_an_invalid_measurement_never_moves() -> None:
    with ExitStack() as stack:
        session = open_session(CONFIG, stack)
        args = session.loop_arguments()

        def nan_map(index):
            measured = session.measure(index)
            waves = measured.waves.copy()
            waves[np.nonzero(session.fitter.mask)[0][0], np.nonzero(session.fitter.mask)[1][0]] = np.nan
            return replace(measured, waves=waves)
        args["measure"] = nan_map
        summary = AlignmentLoop(**args, options=options_of(CONFIG), stop=threading.Event()).run()
        commands = session.bench.hexapod.controller.commands
    assert summary.state.phase is AlignPhase.FAULTED and summary.halted is True
    assert not any(c.startswith("MOV") for c in commands)
