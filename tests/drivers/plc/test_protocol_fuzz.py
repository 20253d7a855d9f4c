"""Property tests of the PLC register parsers: hostile registers, round trips, driver against simulator.

What is parsed: register values read from the PLC (status block, output block, any float32/uint32
pair) and the register-map configuration (``RegisterMap.build``). The driver and the simulator
(:mod:`wavestack.simulators.plc.program`, :mod:`~wavestack.simulators.plc.access`) are written twice
on purpose; here each one's encoding is decoded by the other.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import assume, given
from hypothesis import strategies as st

from wavestack.drivers.plc import (WORD_ORDERS, RegisterMap, WriteRefused, decode_float32, decode_float32_array,
                                   decode_outputs, decode_status, decode_uint32, encode_float32, encode_uint32,
                                   round_to_float32)
from wavestack.simulators.plc import PlcSimLayout, PolishingStation
from wavestack.simulators.plc.access import check_request
from wavestack.simulators.plc.faults import SimFaults
from wavestack.simulators.plc.program import PolishingPlcProgram, float_to_words, words_to_float

orders = st.sampled_from(WORD_ORDERS)
#: Anything a register list could hold after a confused transport: in range, negative, huge, bool.
any_register = st.one_of(st.integers(0, 0xFFFF), st.integers(-2**70, 2**70), st.booleans())
register_lists = st.lists(any_register, max_size=12)
every_float = st.floats(allow_nan=True, allow_infinity=True)


def _is_float32_range(value: float) -> bool:
    try:
        struct.pack(">f", value)
    except OverflowError:
        return False
    return True


# ---------------------------------------------------------------------------------------------- (a)
@fuzz_settings(300)
@given(registers=register_lists, order=st.one_of(orders, st.text(max_size=5)))
def test_register_decoders_return_or_raise_value_error(registers: list[int], order: str) -> None:
    for decode in (decode_float32, decode_uint32, decode_float32_array):
        try:
            decode(registers, order)  # type: ignore[arg-type]
        except ValueError:
            pass
    try:
        decode_outputs(registers, order)  # type: ignore[arg-type]
    except ValueError:
        pass


@fuzz_settings(300)
@given(registers=st.lists(st.integers(0, 0xFFFF), min_size=3, max_size=3))
def test_status_block_decodes_every_register_triple(registers: list[int]) -> None:
    status = decode_status(registers)
    assert (status.last_accepted_id, status.heartbeat_echo, status.raw_word) == (registers[1], registers[2],
                                                                                 registers[0])
    assert status.can_accept_command == (registers[0] & 0b1111 == 0b0001)


@fuzz_settings(300)
@given(registers=st.lists(st.integers(0, 0xFFFF), max_size=10).filter(lambda r: len(r) != 3))
def test_status_block_of_the_wrong_length_is_refused(registers: list[int]) -> None:
    with pytest.raises(ValueError, match="status block"):
        decode_status(registers)


# ---------------------------------------------------------------------------------------------- (b)
@fuzz_settings(300)
@given(value=every_float, order=orders)
def test_float32_encoding_round_trips_every_float(value: float, order: str) -> None:
    if not _is_float32_range(value):
        with pytest.raises(ValueError, match="float32 range"):
            encode_float32(value, order)  # type: ignore[arg-type]
        return
    decoded = decode_float32(encode_float32(value, order), order)  # type: ignore[arg-type]
    if math.isnan(value):
        assert math.isnan(decoded)  # documented: NaN is encoded as such
    else:
        assert decoded == round_to_float32(value)
        assert math.copysign(1.0, decoded) == math.copysign(1.0, value)  # -0.0 keeps its sign


@pytest.mark.parametrize("order", WORD_ORDERS)
@pytest.mark.parametrize("value", [0.0, -0.0, 3.4028234663852886e38, -3.4028234663852886e38, 1.401298464324817e-45,
                                   math.inf, -math.inf])
def test_float32_edge_values_round_trip(value: float, order: str) -> None:
    decoded = decode_float32(encode_float32(value, order), order)  # type: ignore[arg-type]
    assert decoded == value and math.copysign(1.0, decoded) == math.copysign(1.0, value)


@fuzz_settings(300)
@given(value=st.one_of(st.integers(0, 2**32 - 1), st.sampled_from([0, 1, 2**16, 2**32 - 1])), order=orders)
def test_uint32_round_trips_at_the_edges(value: int, order: str) -> None:
    assert decode_uint32(encode_uint32(value, order), order) == value  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------- register map (a)
config_ints = st.one_of(st.integers(-5, 300), st.integers(65500, 65540), st.integers(-2**64, 2**64))


_VALID_CONFIG: dict[str, Any] = dict(unit_id=1, word_order="ABCD", self_check_register=0, self_check_value=12345.678,
                                     heartbeat_register=10, rearm_register=11, status_register=20,
                                     command_block=(100, 10), output_block=(200, 10), read_function=3,
                                     single_write_function=6, block_write_function=16)
_HOSTILE: dict[str, st.SearchStrategy[Any]] = dict(
    unit_id=config_ints, word_order=st.one_of(orders, st.text(max_size=4)), self_check_register=config_ints,
    self_check_value=every_float, heartbeat_register=config_ints, rearm_register=config_ints,
    status_register=config_ints, command_block=st.tuples(config_ints, config_ints),
    output_block=st.tuples(config_ints, config_ints), read_function=st.integers(0, 30),
    single_write_function=st.integers(0, 30), block_write_function=st.integers(0, 30))


@st.composite
def map_configs(draw: st.DrawFn) -> dict[str, Any]:
    """A valid configuration with one to three fields replaced by hostile values."""
    config = dict(_VALID_CONFIG)
    for name in draw(st.lists(st.sampled_from(sorted(_HOSTILE)), min_size=1, max_size=3, unique=True)):
        config[name] = draw(_HOSTILE[name])
    return config


@fuzz_settings(300)
@given(config=map_configs())
def test_register_map_configuration_is_built_or_refused_with_value_error(config: dict[str, Any]) -> None:
    try:
        register_map = RegisterMap.build(**config)
    except ValueError:
        return
    # what validates must be usable: the self-check constant survives the driver's own rounding
    round_to_float32(register_map.self_check_value)
    assert 1 <= register_map.n_terms and register_map.command.count <= 123


def test_a_self_check_constant_beyond_float32_is_refused_when_the_map_is_built() -> None:
    # regression: 1e39 validated, then the self-check raised ValueError at start-up, and the
    # simulator could not encode the constant (OverflowError) at all
    with pytest.raises(ValueError, match="self_check_value"):
        RegisterMap.build(unit_id=1, word_order="ABCD", self_check_register=0, self_check_value=1e39,
                          heartbeat_register=10, rearm_register=11, status_register=20, command_block=(100, 4),
                          output_block=(200, 4))


# ----------------------------------------------------------------- (c) driver against the simulator
def _layouts(n_terms: int, orders_: tuple[str, str, str], single_write: int,
             read_function: int) -> tuple[RegisterMap, PlcSimLayout]:
    self_check_order, command_order, output_order = orders_
    count = 2 + 2 * n_terms
    driver = RegisterMap.build(unit_id=1, word_order="ABCD", self_check_register=0, self_check_value=12345.678,
                               heartbeat_register=10, rearm_register=11, status_register=20,
                               command_block=(100, count), output_block=(200, count), read_function=read_function,
                               single_write_function=single_write,  # type: ignore[arg-type]
                               self_check_word_order=self_check_order,  # type: ignore[arg-type]
                               command_word_order=command_order,  # type: ignore[arg-type]
                               output_word_order=output_order)  # type: ignore[arg-type]
    sim = PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=12345.678,
                       self_check_word_order=self_check_order, heartbeat_register=10, rearm_register=11,
                       status_register=20, command_block=(100, count), output_block=(200, count),
                       command_word_order=command_order, output_word_order=output_order, watchdog_timeout_s=60.0,
                       read_function=read_function, single_write_function=single_write)
    return driver, sim


@fuzz_settings(300)
@given(value=st.floats(width=32), order=orders)
def test_simulator_decodes_what_the_driver_encodes_and_back(value: float, order: str) -> None:
    sent = list(encode_float32(value, order))  # type: ignore[arg-type]
    assert float_to_words(value, order) == sent
    back = words_to_float(sent, order)
    assert (math.isnan(back) and math.isnan(value)) or (back == value and str(back) == str(value))
    assert str(decode_float32(float_to_words(value, order), order)) == str(value)  # type: ignore[arg-type]


@fuzz_settings(150)
@given(n_terms=st.integers(1, 4), data=st.data(), orders_=st.tuples(orders, orders, orders),
       command_id=st.integers(1, 0xFFFF), passes=st.integers(1, 100))
def test_a_command_the_driver_encodes_is_the_command_the_simulated_plc_applies(
        n_terms: int, data: st.DataObject, orders_: tuple[str, str, str], command_id: int, passes: int) -> None:
    driver, sim_layout = _layouts(n_terms, orders_, 6, 3)
    removal = data.draw(st.lists(st.floats(-500.0, 500.0), min_size=n_terms, max_size=n_terms))
    program = PolishingPlcProgram(sim_layout, PolishingStation([0.0] * n_terms, noise_nm=0.0), SimFaults())
    memory = [0] * 300
    assert program.on_request(10, [1], 0.0, 0, memory) is None  # the first heartbeat arms the watchdog
    words = driver.encode_command(command_id, passes, removal)
    assert program.on_request(driver.command.start, words, 0.0, 0, memory) is None
    expected = tuple(round_to_float32(v) for v in removal)
    assert program.accepted_removals[-1] == expected
    status = decode_status(memory[driver.status.start:driver.status.stop])
    assert status.last_accepted_id == command_id and status.heartbeat_echo == 1
    assert driver.output.word_order is not None
    outputs = decode_outputs(memory[driver.output.start:driver.output.stop], driver.output.word_order)
    assert outputs.spindle_enabled and outputs.active_command_id == command_id
    assert tuple(outputs.setpoint_nm) == expected


@fuzz_settings(300)
@given(address=st.integers(0, 260), count=st.integers(1, 14), code=st.sampled_from([3, 4, 6, 16, 5, 15, 23]),
       single_write=st.sampled_from([6, 16]), read_function=st.sampled_from([3, 4]))
def test_the_driver_allow_list_never_permits_a_write_the_plc_refuses(address: int, count: int, code: int,
                                                                     single_write: int, read_function: int) -> None:
    driver, sim_layout = _layouts(4, ("ABCD", "ABCD", "ABCD"), single_write, read_function)
    try:
        driver.check_write(address, count, code)
    except WriteRefused:
        allowed = False
    else:
        allowed = True
    assert allowed == (check_request(sim_layout, code, address, count, writing=True) is None)


def test_a_partial_command_block_write_is_refused_as_the_plc_refuses_it() -> None:
    # regression: the allow-list let FC16 write registers 102-103 alone; the PLC answers exception 2
    # (a new id would start a command from stale registers), so it must not reach the wire at all
    driver, sim_layout = _layouts(4, ("ABCD", "ABCD", "ABCD"), 6, 3)
    assert check_request(sim_layout, 16, 102, 2, writing=True) is not None
    with pytest.raises(WriteRefused, match="whole"):
        driver.check_write(102, 2, 16)
    assert driver.check_write(100, 10, 16).name == "command"


@fuzz_settings(300)
@given(values=st.lists(st.floats(width=32, allow_nan=False), min_size=1, max_size=8), order=orders)
def test_simulator_output_block_decodes_in_the_driver(values: list[float], order: str) -> None:
    registers = [1, 7] + [w for v in values for w in float_to_words(v, order)]
    outputs = decode_outputs(registers, order)  # type: ignore[arg-type]
    assert outputs.setpoint_nm.tolist() == values and not outputs.setpoint_nm.flags.writeable
    assert np.array_equal(np.signbit(outputs.setpoint_nm), np.signbit(np.array(values)))


@fuzz_settings(100)
@given(sign=st.integers(0, 1), mantissa=st.integers(0, 2**23 - 1), order=orders)
def test_a_nan_or_infinity_from_the_wire_decodes_alike_on_both_sides(sign: int, mantissa: int, order: str) -> None:
    bits = (sign << 31) | (0xFF << 23) | mantissa  # exponent all ones: infinity (mantissa 0) or a NaN
    registers = list(encode_uint32(bits, order))  # type: ignore[arg-type]  # the same bytes, as a uint32
    driver_value = decode_float32(registers, order)  # type: ignore[arg-type]
    assert str(driver_value) == str(words_to_float(registers, order))
    assert math.isnan(driver_value) == (mantissa != 0)
