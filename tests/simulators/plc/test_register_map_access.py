"""The simulated PLC answers exactly as its register map says, seen by a plain pymodbus client.

The map (README, ``config/plc-*.toml``): every block is read with one function code (3 by default),
heartbeat and re-arm are written alone with the single-write code (6 by default), the command block
only whole, in one FC16 request; nothing else is written. Expected answers (Modbus Application
Protocol v1.1b3, section 7 and the transaction state diagram of section 4.4, which checks the function
code before the address):

- a function code the map never uses (FC4 on a holding-register map, coils, FC22, FC23, FC6 on a
  map whose single writes are FC16): exception 1, at any address, since this PLC does not serve it;
- a function code the map uses, aimed at a block the map does not allow it for (FC6 into the command
  block, FC16 onto the heartbeat), or a command write that covers only part of the block: exception
  2, and nothing is written or started.

``sim.requests`` is what the simulator decoded from the wire, so each test also checks that the
request arrived as sent.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from pymodbus.client import ModbusTcpClient

from wavestack.simulators.plc import PlcSimLayout, PlcSimulator, PolishingStation
from wavestack.simulators.plc.program import float_to_words

N_TERMS = 2
HEARTBEAT, REARM, STATUS, COMMAND, OUTPUT = 10, 11, 20, 100, 200
COMMAND_COUNT = 2 + 2 * N_TERMS


def layout(**functions: int) -> PlcSimLayout:
    return PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=1.5, self_check_word_order="ABCD",
                        heartbeat_register=HEARTBEAT, rearm_register=REARM, status_register=STATUS,
                        command_block=(COMMAND, COMMAND_COUNT), output_block=(OUTPUT, COMMAND_COUNT),
                        command_word_order="ABCD", output_word_order="ABCD", watchdog_timeout_s=60.0,
                        **functions)


@contextmanager
def served(**functions: int) -> Iterator[tuple[PlcSimulator, ModbusTcpClient]]:
    with PlcSimulator(layout(**functions), PolishingStation((5.0, 5.0), noise_nm=0.0, seed=1)) as sim:
        client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=1.0, retries=0)
        try:
            assert client.connect()
            yield sim, client
        finally:
            client.close()


def command(command_id: int, removal_nm: tuple[float, float] = (1.0, 2.0)) -> list[int]:
    words = [w for value in removal_nm for w in float_to_words(value, "ABCD")]
    return [command_id, 1, *words]


def exception_code(reply: object) -> int | None:
    return reply.exception_code if reply.isError() else None  # type: ignore[attr-defined]


def start_heartbeat(client: ModbusTcpClient) -> None:
    assert exception_code(client.write_register(HEARTBEAT, 1, device_id=1)) is None


def test_the_documented_accesses_work() -> None:
    with served() as (sim, client):
        start_heartbeat(client)
        assert exception_code(client.write_registers(COMMAND, command(7), device_id=1)) is None
        assert sim.accepted_commands == [7]
        assert client.read_holding_registers(STATUS, count=3, device_id=1).registers[1] == 7
        assert client.read_holding_registers(OUTPUT, count=2, device_id=1).registers == [1, 7]
        assert exception_code(client.write_register(REARM, 0, device_id=1)) is None


def test_fc6_into_the_command_block_is_refused_and_starts_nothing() -> None:
    with served() as (sim, client):
        start_heartbeat(client)
        client.write_registers(COMMAND, command(7), device_id=1)
        # a new id alone would start a command from the registers of the last one
        for address, value in ((COMMAND, 8), (COMMAND + 1, 3), (COMMAND + 2, 0)):
            assert exception_code(client.write_register(address, value, device_id=1)) == 2
            assert sim.requests[-1].function_code == 6 and sim.requests[-1].address == address
        assert sim.accepted_commands == [7]
        assert client.read_holding_registers(COMMAND, count=2, device_id=1).registers == [7, 1]


@pytest.mark.parametrize(("address", "values"), [
    (COMMAND, [9]),                                  # the id alone
    (COMMAND, command(9)[:4]),                       # id, passes and the first term
    (COMMAND + 1, command(9)[1:]),                   # all but the id
    (COMMAND, command(9) + [0]),                     # one register too many (into the gap)
])
def test_a_command_write_must_cover_the_whole_block(address: int, values: list[int]) -> None:
    with served() as (sim, client):
        start_heartbeat(client)
        assert exception_code(client.write_registers(address, values, device_id=1)) == 2
        record = sim.requests[-1]
        assert (record.function_code, record.address, record.values) == (16, address, tuple(values))
        assert sim.accepted_commands == []
        assert client.read_holding_registers(COMMAND, count=COMMAND_COUNT, device_id=1).registers == \
            [0] * COMMAND_COUNT


def test_fc16_onto_the_heartbeat_is_refused_when_the_map_says_fc6() -> None:
    with served() as (sim, client):
        for address, values in ((HEARTBEAT, [5]), (REARM, [1]), (HEARTBEAT, [5, 1])):
            assert exception_code(client.write_registers(address, values, device_id=1)) == 2
            assert sim.requests[-1].values == tuple(values)
        assert sim.heartbeat_value == 0  # the watchdog saw no beat


def test_function_codes_the_map_never_uses_answer_exception_1_anywhere() -> None:
    with served() as (sim, client):
        start_heartbeat(client)
        for address in (0, STATUS, COMMAND, OUTPUT, 150):  # mapped blocks and a gap alike
            assert exception_code(client.read_input_registers(address, count=1, device_id=1)) == 1
            assert exception_code(client.read_coils(address, count=1, device_id=1)) == 1
            assert exception_code(client.write_coil(address, True, device_id=1)) == 1
            assert exception_code(client.mask_write_register(address=address, and_mask=0xFFFF, or_mask=0, device_id=1)) == 1
            assert exception_code(client.readwrite_registers(read_address=address, read_count=1,
                                                             write_address=address, values=[1],
                                                             device_id=1)) == 1
        assert sim.accepted_commands == [] and sim.heartbeat_value == 1


def test_a_map_read_with_fc4_and_written_with_fc16_refuses_fc3_and_fc6() -> None:
    with served(read_function=4, single_write_function=16) as (sim, client):
        assert exception_code(client.write_registers(HEARTBEAT, [1], device_id=1)) is None
        assert sim.heartbeat_value == 1
        assert client.read_input_registers(STATUS, count=3, device_id=1).registers[2] == 1  # the echo
        assert exception_code(client.read_holding_registers(STATUS, count=3, device_id=1)) == 1
        assert exception_code(client.write_register(HEARTBEAT, 2, device_id=1)) == 1
        assert exception_code(client.write_registers(COMMAND, command(3), device_id=1)) is None
        assert sim.accepted_commands == [3]


def test_the_layout_checks_its_function_codes() -> None:
    with pytest.raises(ValueError, match="read_function"):
        layout(read_function=6)
    with pytest.raises(ValueError, match="single_write_function"):
        layout(single_write_function=3)
