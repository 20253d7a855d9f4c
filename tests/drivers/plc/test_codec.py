"""float32/uint32 in two registers: the four byte orders, checked against the README table."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.plc import (
    WORD_ORDERS,
    decode_float32,
    decode_float32_array,
    decode_uint32,
    encode_float32,
    encode_float32_array,
    encode_uint32,
    round_to_float32,
)
from wavestack.simulators.plc.program import float_to_words, words_to_float

orders = st.sampled_from(WORD_ORDERS)
float32s = st.floats(width=32, allow_nan=False)
registers = st.integers(min_value=0, max_value=0xFFFF)


def _expected_registers(value_bytes: bytes, order: str) -> tuple[int, int]:
    """Spell the table out: the order's letters name the value's bytes A..D as they sit on the wire."""
    byte = {letter: value_bytes[i] for i, letter in enumerate("ABCD")}
    wire = [byte[letter] for letter in order]
    return wire[0] * 256 + wire[1], wire[2] * 256 + wire[3]


@pytest.mark.parametrize("order", WORD_ORDERS)
def test_known_constant_lands_on_the_wire_as_the_table_says(order: str) -> None:
    packed = struct.pack(">f", 12345.678)  # 0x4640E6B6: four distinct bytes, so every order differs
    assert encode_float32(12345.678, order) == _expected_registers(packed, order)  # type: ignore[arg-type]


def test_the_four_orders_give_four_different_register_pairs() -> None:
    pairs = {encode_float32(12345.678, order) for order in WORD_ORDERS}
    assert len(pairs) == 4


@fuzz_settings(300)
@given(value=float32s, order=orders)
def test_float32_round_trips_in_every_order(value: float, order: str) -> None:
    regs = encode_float32(value, order)  # type: ignore[arg-type]
    assert all(0 <= r <= 0xFFFF for r in regs)
    assert decode_float32(regs, order) == value  # type: ignore[arg-type]  # float32 values are exact


@fuzz_settings(300)
@given(first=registers, second=registers, order=orders)
def test_every_register_pair_decodes_and_re_encodes_bit_exactly(first: int, second: int, order: str) -> None:
    value = decode_float32([first, second], order)  # type: ignore[arg-type]
    if math.isnan(value):  # a signalling NaN may come back quiet: only NaN-ness is guaranteed
        assert math.isnan(decode_float32(encode_float32(value, order), order))  # type: ignore[arg-type]
    else:
        assert encode_float32(value, order) == (first, second)  # type: ignore[arg-type]


@fuzz_settings(300)
@given(value=float32s, order=orders)
def test_driver_codec_agrees_with_the_simulators_independent_one(value: float, order: str) -> None:
    assert list(encode_float32(value, order)) == float_to_words(value, order)  # type: ignore[arg-type]
    assert words_to_float(list(encode_float32(value, order)), order) == value  # type: ignore[arg-type]


@fuzz_settings(300)
@given(value=st.integers(min_value=0, max_value=2**32 - 1), order=orders)
def test_uint32_round_trips_and_follows_the_table(value: int, order: str) -> None:
    regs = encode_uint32(value, order)  # type: ignore[arg-type]
    assert regs == _expected_registers(value.to_bytes(4, "big"), order)
    assert decode_uint32(regs, order) == value  # type: ignore[arg-type]


@fuzz_settings(100)
@given(values=st.lists(float32s, min_size=1, max_size=20), order=orders)
def test_arrays_round_trip(values: list[float], order: str) -> None:
    regs = encode_float32_array(values, order)  # type: ignore[arg-type]
    assert len(regs) == 2 * len(values)
    np.testing.assert_array_equal(decode_float32_array(regs, order), np.array(values))  # type: ignore[arg-type]


def test_values_round_to_the_nearest_float32() -> None:
    expected = float(np.float32(0.1))
    assert decode_float32(encode_float32(0.1, "CDAB"), "CDAB") == expected
    assert round_to_float32(0.1) == expected


def test_infinities_and_nan_are_encoded() -> None:
    assert decode_float32(encode_float32(math.inf, "BADC"), "BADC") == math.inf
    assert math.isnan(decode_float32(encode_float32(math.nan, "DCBA"), "DCBA"))


@pytest.mark.parametrize(("call", "message"), [
    (lambda: encode_float32(1.0, "ACBD"), "unknown byte order 'ACBD'"),  # type: ignore[arg-type]
    (lambda: encode_float32(1e39, "ABCD"), "out of the float32 range"),
    (lambda: round_to_float32(-1e39), "out of the float32 range"),
    (lambda: decode_float32([1, 2, 3], "ABCD"), "exactly 2 registers"),
    (lambda: decode_float32([1, 0x10000], "ABCD"), "not a 16-bit unsigned integer"),
    (lambda: decode_float32([-1, 0], "ABCD"), "not a 16-bit unsigned integer"),
    (lambda: encode_uint32(2**32, "ABCD"), "not an unsigned 32-bit integer"),
    (lambda: encode_uint32(-1, "ABCD"), "not an unsigned 32-bit integer"),
    (lambda: decode_float32_array([1, 2, 3], "ABCD"), "even number of registers"),
    (lambda: encode_float32_array([[1.0]], "ABCD"), "1-D vector"),
])
def test_bad_input_is_refused_with_a_message(call: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()  # type: ignore[operator]
