"""The PLC driver against the simulated PLC over loopback Modbus/TCP.

Faults are injected through the simulator's own switches; every expectation comes from the
simulator's ground truth (accepted commands, watchdog state, outputs, the requests it decoded, the
terms its display shows).
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from wavestack.drivers import DeviceDisconnected, DeviceTimeout, ProtocolError
from wavestack.drivers.plc import (
    WORD_ORDERS,
    HeartbeatEchoStale,
    LinkTiming,
    PlcNotReady,
    PlcRefused,
    PolishingLink,
    RegisterMap,
    WriteRefused,
    round_to_float32,
)
from wavestack.simulators.plc import PlcSimLayout, PlcSimulator, PolishingStation, WatchdogState

N_TERMS = 4
SURFACE_NM = (10.0, 20.0, 30.0, 40.0)
REMOVAL_NM = np.array([1.5, -2.25, 3.1, 0.1])
CONSTANT = 12345.678
# The I/O timeout is far above a loopback round trip, so only injected faults time out.
TIMING = LinkTiming(io_timeout_s=0.5, reconnect_initial_s=0.02, reconnect_max_s=0.2, command_retries=2,
                    heartbeat_echo_max_lag=2)
LONG_WATCHDOG_S = 60.0  # never trips during a test that is not about the watchdog
WAIT_S = 10.0  # generous bound for waiting on a state change; never a timing assertion


def make_station() -> PolishingStation:
    return PolishingStation(SURFACE_NM, noise_nm=0.5, seed=3)


def make_layout(order: str = "CDAB", watchdog_timeout_s: float = LONG_WATCHDOG_S,
                pass_duration_s: float = 0.0, **functions: int) -> PlcSimLayout:
    return PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=CONSTANT, self_check_word_order=order,
                        heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20,
                        command_block=(100, 2 + 2 * N_TERMS), output_block=(200, 2 + 2 * N_TERMS),
                        command_word_order=order, output_word_order=order, watchdog_timeout_s=watchdog_timeout_s,
                        pass_duration_s=pass_duration_s, **functions)


def make_map(order: str = "CDAB", **functions: int) -> RegisterMap:
    return RegisterMap.build(unit_id=1, word_order=order, self_check_register=0,  # type: ignore[arg-type]
                             self_check_value=CONSTANT, heartbeat_register=10, rearm_register=11, owner_register=12,
                             status_register=20, command_block=(100, 2 + 2 * N_TERMS),
                             output_block=(200, 2 + 2 * N_TERMS), **functions)


@contextmanager
def plc(order: str = "CDAB", map_order: str | None = None, **layout: float) -> Iterator[tuple[PlcSimulator,
                                                                                              PolishingLink]]:
    with PlcSimulator(make_layout(order, **layout), make_station()) as sim:
        with PolishingLink("127.0.0.1", sim.port, make_map(map_order or order), TIMING) as link:
            yield sim, link


def ready(link: PolishingLink) -> None:
    link.connect(timeout_s=2.0)
    link.self_check(timeout_s=1.0)


def as_float32(values: np.ndarray) -> np.ndarray:
    return np.array([round_to_float32(v) for v in values])


def wait_for(condition: Callable[[], bool]) -> bool:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


@pytest.mark.parametrize("order", WORD_ORDERS)
def test_each_byte_order_round_trips_through_the_plc(order: str) -> None:
    with plc(order) as (sim, link):
        status = link.connect(timeout_s=2.0)
        assert status.ready and status.last_accepted_id == 0
        assert link.self_check(timeout_s=1.0) == round_to_float32(CONSTANT)
        ack = link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=2.0)
        assert (ack.command_id, ack.attempts, ack.status.last_accepted_id) == (1, 1, 1)
        sent = as_float32(REMOVAL_NM)  # what float32 can carry; equality below is exact
        np.testing.assert_array_equal(sim.outputs.setpoint_nm, sent)
        outputs = link.read_outputs(timeout_s=1.0)
        assert outputs.spindle_enabled and outputs.active_command_id == 1
        np.testing.assert_array_equal(outputs.setpoint_nm, sent)
        # commands publish the terms for the display and remove nothing (issue 14: removal only through jobs)
        assert sim.station.displayed == (1, tuple(sent))
        np.testing.assert_array_equal(sim.station.surface_nm, SURFACE_NM)


@pytest.mark.parametrize(("actual", "configured"), list(zip(WORD_ORDERS, WORD_ORDERS[1:] + WORD_ORDERS[:1])))
def test_self_check_fails_closed_on_a_mismatched_word_order(actual: str, configured: str) -> None:
    with plc(actual, map_order=configured) as (sim, link):
        link.connect(timeout_s=2.0)
        with pytest.raises(ProtocolError, match=f"configured word order {configured}.*decodes correctly with "
                                                f"word order {actual}"):
            link.self_check(timeout_s=1.0)
        with pytest.raises(ProtocolError, match="self-check has not passed"):
            link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=1.0)
        assert sim.accepted_commands == []
        assert not any(r.function_code == 16 and r.address == 100 for r in sim.requests)


def test_a_command_before_the_self_check_is_refused_without_a_packet() -> None:
    with plc() as (sim, link):
        link.connect(timeout_s=2.0)
        with pytest.raises(ProtocolError, match="self-check has not passed"):
            link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=1.0)
        assert not any(r.function_code == 16 and r.address == 100 for r in sim.requests)


def test_handshake_applies_a_command_exactly_once_under_retries_and_a_dropped_reply() -> None:
    with plc() as (sim, link):
        ready(link)
        sim.faults.drop_replies(1, function_code=16)  # the PLC executes the write, the host never hears so
        ack = link.send_removal(5, REMOVAL_NM, passes=2, timeout_s=3.0)
        assert ack.attempts == 2 and ack.status.last_accepted_id == 5
        again = link.send_removal(5, REMOVAL_NM, passes=2, timeout_s=2.0)  # the caller retries too
        assert again.attempts == 1
        command_writes = [r for r in sim.requests if r.function_code == 16 and r.values[:1] == (5,)]
        assert len(command_writes) == 3  # three sends of id 5 reached the PLC ...
        assert sim.accepted_commands == [5]  # ... and it took effect once
        assert sim.station.displays == 1 and sim.station.displayed == (5, tuple(as_float32(REMOVAL_NM)))
        count = sim.request_count
        with pytest.raises(ValueError, match="already sent with other parameters"):
            link.send_removal(5, REMOVAL_NM * 2, passes=2, timeout_s=1.0)
        assert sim.request_count == count


def test_watchdog_trips_when_heartbeats_stop_and_the_driver_reports_it() -> None:
    with plc(watchdog_timeout_s=1.0) as (sim, link):
        ready(link)
        link.heartbeat(timeout_s=1.0)
        link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=2.0)
        assert not sim.outputs.all_zero
        beat = sim.heartbeat_value

        def tripped() -> bool:
            # neither reads nor rewriting the same heartbeat value count as activity
            if link.read_status(timeout_s=1.0).watchdog_tripped:
                return True
            try:
                link.write_registers(10, [beat], timeout_s=1.0)
            except PlcRefused as error:  # tripped between the read and the write
                return error.exception_code == 4
            return False

        assert wait_for(tripped)
        assert sim.watchdog_state is WatchdogState.TRIPPED and sim.watchdog_trips == 1
        assert sim.outputs.all_zero
        status = link.read_status(timeout_s=1.0)
        assert status.watchdog_tripped and not status.ready and status.last_accepted_id is None
        with pytest.raises(PlcRefused, match="exception 4") as caught:
            link.heartbeat(timeout_s=1.0)
        assert (caught.value.exception_code, caught.value.function_code, caught.value.address) == (4, 6, 10)
        writes = sum(r.function_code == 16 for r in sim.requests)
        with pytest.raises(PlcNotReady, match="tripped"):  # the gate: nothing reaches the wire
            link.send_removal(2, REMOVAL_NM, passes=1, timeout_s=1.0)
        assert sim.accepted_commands == [1] and sum(r.function_code == 16 for r in sim.requests) == writes
        with pytest.raises(PlcRefused):
            link.read_outputs(timeout_s=1.0)
        rearmed = link.rearm(timeout_s=1.0)
        assert not rearmed.watchdog_tripped and rearmed.last_accepted_id == 1
        assert sim.watchdog_trips == 1 and sim.outputs.all_zero  # outputs stay zero until a new command


def test_server_restart_mid_run_and_the_driver_recovers_heartbeat_first() -> None:
    with plc() as (sim, link):
        ready(link)
        link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=2.0)
        seen = len(sim.requests)
        sim.restart(downtime_s=0.3)
        with pytest.raises(DeviceDisconnected, match="connection lost"):
            link.heartbeat(timeout_s=1.0)  # the loss is reported at once, not after a timeout

        def heartbeat_ok() -> bool:
            try:
                link.heartbeat(timeout_s=0.2)
            except (DeviceDisconnected, DeviceTimeout):  # refused while the server is down, or backing off
                return False
            return True

        assert wait_for(heartbeat_ok)
        assert link.reconnects >= 1 and sim.connections == 1 + link.reconnects
        link.send_removal(2, REMOVAL_NM, passes=1, timeout_s=2.0)
        assert sim.accepted_commands == [1, 2]
        writes = [r for r in sim.requests[seen:] if r.function_code in (6, 16)]
        # on the new connection the claim comes first (the owner block, this link's token), then the heartbeat
        assert [(w.function_code, w.address) for w in writes[:2]] == [(16, 12), (6, 10)]
        writes = writes[1:]
        command_index = next(i for i, r in enumerate(writes) if r.address == 100)
        assert all(r.address == 10 for r in writes[:command_index])


def test_a_write_outside_the_allow_list_is_refused_without_a_packet() -> None:
    with plc() as (sim, link):
        link.connect(timeout_s=2.0)
        count = sim.request_count
        for address, values in ((200, [1]), (20, [0, 0, 0]), (0, [1, 2]), (150, [1]), (99, [1, 2]), (108, [1] * 4)):
            with pytest.raises(WriteRefused, match=f"refusing to write register[s]? {address}"):
                link.write_registers(address, values, timeout_s=1.0)
        assert sim.request_count == count
        link.read_status(timeout_s=1.0)  # a round trip: everything sent before it has been decoded
        assert sim.request_count == count + 1
        assert (sim.requests[-1].function_code, sim.requests[-1].address) == (3, 20)


@pytest.mark.parametrize(("fault", "error"), [
    ("truncate", ProtocolError),
    ("corrupt", ProtocolError),
    ("drop", DeviceTimeout),
    ("delay", DeviceTimeout),
])
def test_bad_replies_raise_our_typed_error_and_the_next_request_succeeds(fault: str, error: type) -> None:
    with plc() as (sim, link):
        ready(link)
        link.send_removal(3, REMOVAL_NM, passes=1, timeout_s=2.0)
        if fault == "truncate":
            sim.faults.truncate_replies(1, keep_bytes=10)
        elif fault == "corrupt":
            sim.faults.corrupt_replies(1)
        elif fault == "drop":
            sim.faults.drop_replies(1)
        else:
            sim.faults.delay_s = 3 * TIMING.io_timeout_s
        with pytest.raises(error, match=r"FC3 at register 20 \(unit 1\)") as caught:
            link.read_status(timeout_s=1.0)
        assert type(caught.value) is error  # a timeout is not reported as a protocol error, nor vice versa
        sim.faults.clear()
        status = link.read_status(timeout_s=1.0)
        assert status.last_accepted_id == sim.last_accepted_id == 3 and status.ready


def test_out_of_range_parameters_answer_exception_3_and_change_nothing() -> None:
    with plc() as (sim, link):
        ready(link)
        before = sim.station.surface_nm
        too_deep = REMOVAL_NM.copy()
        too_deep[2] = sim.station.max_removal_nm + 1.0
        for removal, passes in ((too_deep, 1), (REMOVAL_NM, 101)):  # the model allows 1..100 passes
            with pytest.raises(PlcRefused, match="exception 3") as caught:
                link.send_removal(1, removal, passes=passes, timeout_s=1.0)
            assert caught.value.exception_code == 3
        np.testing.assert_array_equal(sim.station.surface_nm, before)
        assert sim.station.displayed is None
        assert link.read_status(timeout_s=1.0).fault and sim.accepted_commands == []
        assert link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=2.0).status.fault is False  # id reusable


def test_read_only_and_unmapped_registers_answer_exception_2_on_the_wire() -> None:
    with plc() as (sim, _link):
        client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=1.0, retries=0)
        try:
            assert client.connect()
            for address in (20, 200, 0, 150):  # status, outputs, self-check constant, a gap in the map
                reply = client.write_register(address, 1, device_id=1)
                assert reply.isError() and reply.exception_code == 2, address
            assert client.read_holding_registers(150, count=1, device_id=1).exception_code == 2
            assert len(client.read_holding_registers(0, count=2, device_id=1).registers) == 2
            # the map reads holding registers: this PLC serves no FC4 (tests/simulators/plc/test_register_map_access.py)
            assert client.read_input_registers(0, count=2, device_id=1).exception_code == 1
        finally:
            client.close()


def test_a_frozen_heartbeat_echo_is_detected() -> None:
    with plc() as (sim, link):
        ready(link)
        link.heartbeat(timeout_s=1.0)
        sim.faults.freeze_heartbeat_echo = True
        for _ in range(TIMING.heartbeat_echo_max_lag):  # the echo may trail by max_lag beats ...
            link.heartbeat(timeout_s=1.0)
        with pytest.raises(HeartbeatEchoStale, match="3 beats behind, expected at most 2"):
            link.heartbeat(timeout_s=1.0)  # ... one more is a PLC that stopped scanning


def test_estop_and_busy_refuse_commands() -> None:
    with plc(pass_duration_s=60.0) as (sim, link):
        ready(link)
        sim.faults.estop = True
        status = link.read_status(timeout_s=1.0)
        assert status.estop and status.fault and not status.ready and not status.can_accept_command
        with pytest.raises(PlcNotReady, match="emergency stop"):  # the gate: the status read before it
            link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=1.0)
        sim.faults.estop = False
        assert link.send_removal(1, REMOVAL_NM, passes=1, timeout_s=1.0).status.busy
        with pytest.raises(PlcNotReady, match="busy"):
            link.send_removal(2, REMOVAL_NM, passes=1, timeout_s=1.0)
        assert sim.accepted_commands == [1]
        assert [r.values[0] for r in sim.requests if r.function_code == 16 and r.address == 100] == [1]  # the accepted


def test_no_server_fails_with_device_disconnected_and_backs_off() -> None:
    with socket.socket() as probe:  # a port nobody listens on once the probe is closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with PolishingLink("127.0.0.1", port, make_map(), TIMING) as link:
        with pytest.raises(DeviceDisconnected, match=f"cannot connect to 127.0.0.1:{port}"):
            link.connect(timeout_s=0.3)
        with pytest.raises(DeviceDisconnected):
            link.heartbeat(timeout_s=0.01)
        assert not link.connected


def test_reconnect_back_off_doubles_and_is_capped() -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    timing = LinkTiming(io_timeout_s=0.5, reconnect_initial_s=0.01, reconnect_max_s=0.04)
    delays = []
    with PolishingLink("127.0.0.1", port, make_map(), timing) as link:
        for _ in range(5):
            time.sleep(2 * timing.reconnect_max_s)  # past the back-off: the next call makes one attempt
            with pytest.raises(DeviceDisconnected, match="next attempt in") as caught:
                link.heartbeat(timeout_s=0.001)
            delays.append(float(caught.value.detail.rsplit("next attempt in ", 1)[1].split(" s")[0]))
    assert delays == [0.01, 0.02, 0.04, 0.04, 0.04]  # initial, doubled, then capped at the maximum


def test_arguments_are_checked_before_any_io() -> None:
    with pytest.raises(ValueError, match="port"):
        PolishingLink("127.0.0.1", 0, make_map(), TIMING)
    with pytest.raises(ValueError, match="timeout_s"):
        PolishingLink("127.0.0.1", 502, make_map(), TIMING).heartbeat(timeout_s=0.0)
    with pytest.raises(ValueError, match="io_timeout_s"):
        LinkTiming(io_timeout_s=0.0)


@pytest.mark.parametrize(("read", "single"), [(3, 6), (4, 16), (3, 16), (4, 6)])
def test_the_driver_speaks_each_function_code_pair_a_map_may_name(read: int, single: int) -> None:
    """End to end with a simulator that refuses every function code its map does not name."""
    functions = {"read_function": read, "single_write_function": single}
    with PlcSimulator(make_layout(watchdog_timeout_s=1.0, **functions), make_station()) as sim:
        with PolishingLink("127.0.0.1", sim.port, make_map(**functions), TIMING) as link:
            ready(link)
            link.heartbeat(timeout_s=1.0)
            ack = link.send_removal(4, REMOVAL_NM, passes=1, timeout_s=2.0)
            assert ack.status.last_accepted_id == 4 and link.read_outputs(timeout_s=1.0).active_command_id == 4
            assert wait_for(lambda: sim.watchdog_state is WatchdogState.TRIPPED)
            link.rearm(timeout_s=1.0)
            assert sim.watchdog_state is WatchdogState.RUNNING
        assert {record.function_code for record in sim.requests} == {read, single, 16}

