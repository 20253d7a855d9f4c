"""The register map: consistency checks, the block layouts (command, status, outputs), the write allow-list."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers import LimitError
from wavestack.drivers.plc import (RegisterMap, WriteRefused, decode_float32_array, decode_outputs, decode_status,
                                   encode_float32_array)

N_TERMS = 4


def build(**overrides: Any) -> RegisterMap:
    values: dict[str, Any] = dict(unit_id=1, word_order="CDAB", self_check_register=0, self_check_value=12345.678,
                                  heartbeat_register=10, rearm_register=11, status_register=20,
                                  command_block=(100, 2 + 2 * N_TERMS), output_block=(200, 2 + 2 * N_TERMS))
    values.update(overrides)
    return RegisterMap.build(**values)


def test_a_valid_map_exposes_its_blocks() -> None:
    register_map = build(command_word_order="DCBA")
    assert register_map.n_terms == N_TERMS
    assert [b.name for b in register_map.blocks()] == ["self_check", "heartbeat", "rearm", "status", "command",
                                                        "output"]
    assert register_map.command.word_order == "DCBA"  # per-block override
    assert register_map.output.word_order == "CDAB"  # default
    assert [b.name for b in register_map.blocks() if b.writable] == ["heartbeat", "rearm", "command"]
    table = register_map.markdown_table()
    assert table.count("\n") == 1 + len(register_map.blocks())  # header, rule, one row per block
    assert "| 100-109 | 10 |" in table and "read-only" in table


@pytest.mark.parametrize(("overrides", "message"), [
    (dict(heartbeat_register=20), "overlaps"),
    (dict(command_block=(195, 10)), "overlaps"),
    (dict(command_block=(100, 9)), "2 \\+ 2 n"),
    (dict(command_block=(100, 2)), "2 \\+ 2 n"),
    (dict(output_block=(200, 12)), "same number of terms"),
    (dict(command_block=(100, 126), output_block=(300, 126)), "exceed one read"),
    (dict(command_block=(100, 124), output_block=(300, 124)), "exceed one FC16 write"),
    (dict(command_block=(65530, 10)), "address range"),
    (dict(unit_id=256), "unit_id"),
    (dict(word_order="ABDC"), "unknown word order"),
    (dict(read_function=5), "read function code"),
    (dict(single_write_function=5), "write function code"),
    (dict(block_write_function=6), "write function code"),
    (dict(self_check_value=float("nan")), "finite"),
])
def test_inconsistent_maps_are_refused(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build(**overrides)


def test_writes_inside_the_allow_list_pass() -> None:
    register_map = build()
    assert register_map.check_write(10, 1, 6).name == "heartbeat"
    assert register_map.check_write(11, 1, 6).name == "rearm"
    assert register_map.check_write(100, 10, 16).name == "command"
    with pytest.raises(WriteRefused, match="written whole"):  # as the PLC refuses it (exception 2)
        register_map.check_write(102, 2, 16)


@pytest.mark.parametrize(("address", "count", "code", "message"), [
    (200, 1, 16, "register 200 \\(FC16\\): the host may write only heartbeat \\(register 10, FC6\\), rearm"),
    (20, 3, 16, "registers 20-22"),
    (0, 2, 16, "registers 0-1"),
    (99, 2, 16, "registers 99-100"),  # straddles the command block's start
    (105, 10, 16, "registers 105-114"),  # runs past its end
    (10, 2, 16, "registers 10-11"),  # heartbeat and re-arm are separate blocks
    (10, 1, 16, "heartbeat block is written with FC6 only"),
    (100, 1, 6, "command block is written with FC16 only"),
])
def test_writes_outside_the_allow_list_are_refused(address: int, count: int, code: int, message: str) -> None:
    with pytest.raises(WriteRefused, match=message) as caught:
        build().check_write(address, count, code)
    assert isinstance(caught.value, LimitError) and isinstance(caught.value, ValueError)
    assert caught.value.device == "PLC unit 1"


@fuzz_settings(300)
@given(address=st.integers(0, 300), count=st.integers(1, 20), code=st.sampled_from([6, 16]))
def test_allow_list_matches_its_definition(address: int, count: int, code: int) -> None:
    register_map = build()
    inside = [b for b in (register_map.heartbeat, register_map.rearm, register_map.command)
              if b.start <= address and address + count <= b.start + b.count]
    allowed = bool(inside) and code == inside[0].write_function
    if inside and inside[0] is register_map.command:  # the command block only whole
        allowed = allowed and (address, count) == (register_map.command.start, register_map.command.count)
    try:
        register_map.check_write(address, count, code)
    except WriteRefused:
        assert not allowed
    else:
        assert allowed


def test_command_layout_is_id_passes_then_floats_in_the_blocks_order() -> None:
    register_map = build(command_word_order="BADC")
    removal = np.array([1.5, -2.25, 300.0, 0.125])
    registers = register_map.encode_command(7, 3, removal)
    assert len(registers) == register_map.command.count
    assert registers[:2] == [7, 3]
    np.testing.assert_array_equal(decode_float32_array(registers[2:], "BADC"), removal)  # exact in float32


@pytest.mark.parametrize(("args", "message"), [
    ((0, 1, [0.0] * N_TERMS), "command_id must be an integer 1..65535"),
    ((65536, 1, [0.0] * N_TERMS), "command_id"),
    ((True, 1, [0.0] * N_TERMS), "command_id"),
    ((1, 0, [0.0] * N_TERMS), "passes must be an integer 1..65535"),
    ((1, 1, [0.0] * (N_TERMS + 1)), "shape \\(4,\\)"),
    ((1, 1, [0.0, np.nan, 0.0, 0.0]), "finite"),
])
def test_bad_commands_are_refused_before_encoding(args: tuple[Any, ...], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build().encode_command(*args)


@fuzz_settings(200)
@given(word=st.integers(0, 0xFFFF), last_id=st.integers(0, 0xFFFF), echo=st.integers(0, 0xFFFF))
def test_status_block_decodes_every_bit_pattern(word: int, last_id: int, echo: int) -> None:
    status = decode_status([word, last_id, echo])
    flags = (status.ready, status.busy, status.fault, status.estop, status.heartbeat_seen)
    assert flags == tuple(bool(word >> bit & 1) for bit in range(5))  # bits 0..4, the rest reserved
    assert (status.last_accepted_id, status.heartbeat_echo, status.raw_word) == (last_id, echo, word)
    assert not status.watchdog_tripped
    assert status.can_accept_command == (word & 0b1111 == 0b0001)  # ready, not busy, no fault, no e-stop


def test_output_block_decodes_with_its_byte_order() -> None:
    register_map = build(output_word_order="DCBA")
    setpoint = [0.5, -1.25, 2.0, 400.0]
    registers = [1, 9, *encode_float32_array(setpoint, "DCBA")]
    outputs = decode_outputs(registers, register_map.output.word_order)  # type: ignore[arg-type]
    assert outputs.spindle_enabled and outputs.active_command_id == 9 and not outputs.all_zero
    np.testing.assert_array_equal(outputs.setpoint_nm, setpoint)
    assert decode_outputs([0] * register_map.output.count, "DCBA").all_zero
    with pytest.raises(ValueError, match="2 \\+ 2 n"):
        decode_outputs([0] * 5, "DCBA")
    with pytest.raises(ValueError, match="3 registers"):
        decode_status([0, 0])
