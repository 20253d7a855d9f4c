"""The link's own command safety (issue 13): limits before the wire, the gate, lost replies settled.

Every check decodes what the simulated PLC received (``sim.requests``) or took (``accepted_removals``).
"""

from __future__ import annotations

import gc
import time
import weakref
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from wavestack.drivers import DeviceTimeout
from wavestack.drivers.plc import (
    CommandLimits,
    CommandRefused,
    HeartbeatEchoStale,
    LinkTiming,
    PlcNotReady,
    PlcRefused,
    PolishingLink,
    RegisterMap,
)
from wavestack.simulators.plc import PlcSimLayout, PlcSimulator, PolishingStation, WatchdogState

N_TERMS = 4
TIMING = LinkTiming(io_timeout_s=0.5, reconnect_initial_s=0.02, reconnect_max_s=0.2, command_retries=2,
                    heartbeat_echo_max_lag=2)


def make_map() -> RegisterMap:
    return RegisterMap.build(unit_id=1, word_order="CDAB", self_check_register=0, self_check_value=12345.678,
                             heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20,
                             command_block=(100, 2 + 2 * N_TERMS), output_block=(200, 2 + 2 * N_TERMS))


@contextmanager
def plc(watchdog_timeout_s: float = 60.0) -> Iterator[tuple[PlcSimulator, PolishingLink]]:
    layout = PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=12345.678, self_check_word_order="CDAB",
                          heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20,
                          command_block=(100, 2 + 2 * N_TERMS), output_block=(200, 2 + 2 * N_TERMS),
                          command_word_order="CDAB", output_word_order="CDAB", watchdog_timeout_s=watchdog_timeout_s)
    with PlcSimulator(layout, PolishingStation((10.0, 20.0, 30.0, 40.0), seed=3)) as sim:
        with PolishingLink("127.0.0.1", sim.port, make_map(), TIMING) as link:
            yield sim, link


def ready(link: PolishingLink) -> None:
    link.connect(timeout_s=2.0)
    link.self_check(timeout_s=1.0)


def wait_for(condition: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()

LIMITS = CommandLimits(max_removal_nm=20.0, max_step_nm=5.0)


def _commands(sim) -> list[tuple[int, ...]]:
    """Every command write the PLC decoded (FC16 into the command block)."""
    return [r.values for r in sim.requests if r.function_code == 16 and r.address == 100]


def _send(link: PolishingLink, value: float, timeout_s: float = 2.0):
    return link.send_removal(link.next_command_id(), np.full(N_TERMS, value), passes=1, timeout_s=timeout_s)


def test_limits_refuse_before_the_wire_counting_from_the_acknowledged_command() -> None:
    with plc() as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        with pytest.raises(CommandRefused, match="step on terms \\[1, 2, 3, 4\\]"):
            _send(link, 6.0)  # 6 nm from the 0 nm the machine holds
        _send(link, 5.0)
        with pytest.raises(CommandRefused, match="max_step_nm 5"):
            _send(link, 10.5)
        _send(link, 10.0)
        with pytest.raises(CommandRefused, match="max_removal_nm 20"):
            link.send_removal(link.next_command_id(), [10.0, 10.0, 10.0, -21.0], passes=1, timeout_s=2.0)
        assert len(_commands(sim)) == 2 and np.asarray(sim.program.accepted_removals)[:, 0].tolist() == [5.0, 10.0]


def test_limits_can_only_be_tightened() -> None:
    with plc() as (_sim, link):
        assert link.restrict(LIMITS) == LIMITS
        assert link.restrict(CommandLimits(100.0, 2.0)) == CommandLimits(20.0, 2.0)
        assert link.command_limits == CommandLimits(20.0, 2.0)
    with pytest.raises(ValueError, match="CommandLimits.max_step_nm"):
        CommandLimits(1.0, 0.0)


def test_a_command_whose_replies_were_all_lost_is_settled_before_the_next() -> None:
    """The PLC took the command but the host never heard so: the next step counts from it."""
    with plc() as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        _send(link, 5.0)
        sim.faults.drop_replies(1 + TIMING.command_retries, function_code=16)
        with pytest.raises(DeviceTimeout):
            _send(link, 10.0, timeout_s=3.0)
        assert sim.accepted_commands[-1] == 2  # it took effect
        with pytest.raises(CommandRefused, match="from the held command"):
            _send(link, 15.5)  # within 5 nm of neither
        ack = _send(link, 15.0)  # 5 nm from what the machine really holds (10), and a new id
        assert ack.command_id == 3 and np.asarray(sim.program.accepted_removals)[:, 0].tolist() == [5.0, 10.0, 15.0]


def test_a_command_after_a_lost_reply_gets_a_new_id_and_never_a_value_error() -> None:
    with plc() as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        sim.faults.truncate_replies(1 + TIMING.command_retries, keep_bytes=9, function_code=16)
        first = link.next_command_id()
        with pytest.raises(Exception) as caught:
            link.send_removal(first, np.full(N_TERMS, 1.0), passes=1, timeout_s=3.0)
        assert not isinstance(caught.value, ValueError) or isinstance(caught.value, CommandRefused)
        second = link.next_command_id()
        assert second != first
        link.send_removal(second, np.full(N_TERMS, 2.0), passes=1, timeout_s=2.0)
        assert sim.last_accepted_id == second


def test_no_command_while_the_heartbeat_echo_is_frozen() -> None:
    with plc() as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        link.heartbeat(timeout_s=1.0)
        sim.faults.freeze_heartbeat_echo = True
        with pytest.raises(HeartbeatEchoStale):
            for _ in range(TIMING.heartbeat_echo_max_lag + 1):
                link.heartbeat(timeout_s=1.0)
        with pytest.raises(PlcNotReady, match="stale echo"):
            _send(link, 1.0)
        assert _commands(sim) == []
        sim.faults.freeze_heartbeat_echo = False
        link.heartbeat(timeout_s=1.0)  # echoed again: scanning
        _send(link, 1.0)
        assert len(_commands(sim)) == 1


class _Sentinel:
    """Stands for what a caller holds in its locals (the station: its set of camera frames, ~10 MB)."""


def _caller_kept_alive(call: Callable[[], object], expected: type[Exception]) -> bool:
    """Whether ``call`` raising ``expected`` keeps its caller's locals alive once the caller returned.

    The cyclic garbage collector is off meanwhile, so only a reference cycle can keep them: an error
    that a frame of its own traceback still names (``raise stale`` from a local) does.
    """
    def caller() -> weakref.ref[_Sentinel]:
        held = _Sentinel()
        try:
            call()
        except expected:
            pass
        else:
            raise AssertionError(f"expected {expected.__name__}")
        return weakref.ref(held)

    enabled = gc.isenabled()
    gc.disable()
    try:
        return caller()() is not None
    finally:
        if enabled:
            gc.enable()


def test_refusals_leave_no_reference_cycle_holding_the_callers_frames() -> None:
    # issue 13: each stale heartbeat kept the station's cycle (frames, result) alive until a GC pass
    with plc() as (sim, link):
        ready(link)
        link.heartbeat(timeout_s=1.0)
        sim.faults.freeze_heartbeat_echo = True
        for _ in range(TIMING.heartbeat_echo_max_lag):
            link.heartbeat(timeout_s=1.0)
        assert not _caller_kept_alive(lambda: link.heartbeat(timeout_s=1.0), HeartbeatEchoStale)
        assert not _caller_kept_alive(lambda: _send(link, 1.0), PlcNotReady)  # the stale-echo refusal
        assert _commands(sim) == []


def test_no_command_in_the_echo_lag_window_after_the_program_stops() -> None:
    # the echo may trail by max_lag beats, but a command needs a scan since the previous command
    with plc() as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        link.heartbeat(timeout_s=1.0)
        _send(link, 1.0)
        sim.faults.freeze_heartbeat_echo = True
        link.heartbeat(timeout_s=1.0)  # one beat behind: within the lag tolerance, no error yet
        with pytest.raises(PlcNotReady, match="expected the echo to advance"):
            _send(link, 2.0)
        assert len(_commands(sim)) == 1
        sim.faults.freeze_heartbeat_echo = False
        link.heartbeat(timeout_s=1.0)
        _send(link, 2.0)
        assert len(_commands(sim)) == 2


def test_the_held_command_is_read_back_after_a_trip_and_after_another_clients_command() -> None:
    with plc(watchdog_timeout_s=0.5) as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        _send(link, 5.0)
        assert wait_for(lambda: link.read_status(timeout_s=1.0).watchdog_tripped)  # no heartbeat: tripped
        link.rearm(timeout_s=1.0)  # outputs zeroed by the trip
        with pytest.raises(CommandRefused):
            _send(link, 10.0)  # 10 nm from the 0 the machine holds now, not 5 from the 5 it held
        _send(link, 5.0)
        with PolishingLink("127.0.0.1", sim.port, make_map(), TIMING) as other:  # someone else tries 8 nm
            other.connect(timeout_s=2.0)
            other.self_check(timeout_s=1.0)
            with pytest.raises(PlcRefused) as refused:  # the PLC is the station's: not for this connection
                other.send_removal(other.next_command_id(), np.full(N_TERMS, 8.0), passes=1, timeout_s=2.0)
            assert refused.value.exception_code == 1
        link.heartbeat(timeout_s=1.0)
        _send(link, 13.0 - 5.0)
        assert np.asarray(sim.program.accepted_removals)[:, 0].tolist() == [5.0, 5.0, 8.0]


def test_ids_count_on_from_the_plcs_last_accepted_id() -> None:
    with plc(watchdog_timeout_s=0.5) as (sim, link):
        ready(link)
        _send(link, 1.0)
        _send(link, 1.0)
        link.close()  # the station stops; its watchdog trips; the PLC is nobody's until re-armed
        assert wait_for(lambda: sim.watchdog_state is WatchdogState.TRIPPED)
        with PolishingLink("127.0.0.1", sim.port, make_map(), TIMING) as later:  # a restarted station
            later.rearm(timeout_s=1.0)
            later.self_check(timeout_s=1.0)
            assert later.next_command_id() == 3
            _send(later, 1.0)
        assert sim.accepted_commands == [1, 2, 3]


def test_a_raw_write_cannot_reach_the_command_block() -> None:
    """The commissioning write skips no gate: the command block is written only by send_removal."""
    from wavestack.drivers.plc import WriteRefused

    with plc() as (sim, link):
        ready(link)
        link.restrict(LIMITS)
        with pytest.raises(WriteRefused, match="only by send_removal"):
            link.write_registers(100, [9, 1] + [0] * (2 * N_TERMS), timeout_s=1.0)
        assert _commands(sim) == []
