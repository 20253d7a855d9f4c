"""The GCS 2.0 wire rules as property tests of the pure protocol module."""

from __future__ import annotations

import math

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.pi_gcs import GCS_ERRORS, GcsError, error_meaning
from wavestack.drivers.pi_gcs import protocol as gcs

DEVICE = "test controller"
axis_ids = st.from_regex(r"[A-Z0-9]{1,3}", fullmatch=True)
# reply text: printable ASCII that does not end in a space (a trailing space would mean "more follows")
reply_lines = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=20)
finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


def wire(lines: list[str]) -> bytes:
    """A multi-line reply per PI: every line but the last ends with space + LF, the last with LF."""
    return (" \n".join(lines) + "\n").encode("ascii")


@fuzz_settings(200)
@given(st.lists(reply_lines, min_size=1, max_size=8), st.binary(max_size=20))
def test_a_reply_ends_at_the_first_lf_without_a_space_before_it(lines, rest) -> None:
    data = wire(lines)
    assert gcs.reply_end(data + rest) == len(data)
    parsed, remainder = gcs.split_reply(data + rest, device=DEVICE)
    assert parsed == lines and remainder == rest


@fuzz_settings(200)
@given(st.lists(reply_lines, min_size=1, max_size=8), st.integers(min_value=0, max_value=200))
def test_every_prefix_of_a_reply_is_incomplete(lines, cut) -> None:
    data = wire(lines)
    prefix = data[:min(cut, len(data) - 1)]
    assert gcs.reply_end(prefix) is None
    assert gcs.split_reply(prefix, device=DEVICE) == (None, prefix)


@fuzz_settings(200)
@given(st.binary(max_size=64))
def test_split_reply_takes_any_bytes_without_crashing(data) -> None:
    try:
        lines, rest = gcs.split_reply(data, device=DEVICE)
    except ProtocolError:
        return
    if lines is not None:
        assert len(data) - len(rest) == gcs.reply_end(data)


@fuzz_settings(200)
@given(finite)
def test_numbers_are_fixed_point_and_quantize_is_what_is_sent(value) -> None:
    text = gcs.format_number(value)
    assert "e" not in text.lower() and text == text.strip()
    assert gcs.quantize(value) == float(text)
    assert abs(float(text) - value) <= 5e-10 * (1 + abs(value))  # 9 decimals, plus float rounding


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_never_encoded(bad) -> None:
    with pytest.raises(ValueError, match="finite"):
        gcs.encode_command("MOV", "X", bad)


@fuzz_settings(200)
@given(st.dictionaries(axis_ids, finite, min_size=1, max_size=6))
def test_a_command_is_one_lf_terminated_line_and_axis_values_round_trip(values) -> None:
    data = gcs.encode_axis_values("MOV", values)
    assert data.endswith(b"\n") and data.count(b"\n") == 1
    words = data.decode("ascii").split()
    assert words[0] == "MOV" and words[1::2] == list(values)
    assert [float(w) for w in words[2::2]] == [gcs.quantize(v) for v in values.values()]


@pytest.mark.parametrize("bad", ["X Y", "X\n", "", "X=1", "#"])
def test_axis_identifiers_cannot_smuggle_separators(bad) -> None:
    with pytest.raises(ValueError):
        gcs.encode_command("MOV", bad, 1.0)


@fuzz_settings(200)
@given(st.dictionaries(axis_ids, finite, min_size=1, max_size=6))
def test_axis_value_replies_round_trip(values) -> None:
    data = wire([f"{axis}={value!r}" for axis, value in values.items()])
    lines, rest = gcs.split_reply(data, device=DEVICE)
    assert rest == b"" and gcs.parse_axis_values(lines, device=DEVICE, what="POS?") == values


@pytest.mark.parametrize("lines", [["X=1", "X=2"], ["X=nan"], ["X"], ["X=1 Y=2"], ["=3"]])
def test_malformed_axis_values_are_protocol_errors(lines) -> None:
    with pytest.raises(ProtocolError, match="POS"):
        gcs.parse_axis_values(lines, device=DEVICE, what="POS?")


def test_flags_are_zero_or_one() -> None:
    assert gcs.parse_axis_flags(["X=1", "Y=0"], device=DEVICE, what="ONT?") == {"X": True, "Y": False}
    with pytest.raises(ProtocolError, match="0 or 1"):
        gcs.parse_axis_flags(["X=2"], device=DEVICE, what="ONT?")


@fuzz_settings(200)
@given(st.lists(st.booleans(), min_size=1, max_size=8), st.booleans())
def test_motion_status_is_a_hex_mask_bit_i_for_axis_i(moving, prefix) -> None:
    axes = tuple(f"A{i}" for i in range(len(moving)))
    mask = sum(1 << i for i, m in enumerate(moving) if m)
    text = ("0x" if prefix else "") + f"{mask:X}"
    assert gcs.parse_motion_mask([text], axes, device=DEVICE) == dict(zip(axes, moving))


def test_single_byte_commands_have_no_lf() -> None:
    assert (gcs.MOTION_STATUS, gcs.READY_STATUS, gcs.STOP_ALL) == (b"\x05", b"\x07", b"\x18")


@pytest.mark.parametrize("reply", [b"\xb1", b"\xb2\n", b"1\n", b"\xb1\n\n", b""])
def test_ready_reply_must_be_b1_or_b0_then_lf(reply) -> None:
    with pytest.raises(ProtocolError, match="0xB1"):
        gcs.parse_ready(reply, device=DEVICE)


def test_err_reply_is_one_integer() -> None:
    assert gcs.parse_error_code(["0"], device=DEVICE) == 0
    with pytest.raises(ProtocolError, match="ERR"):
        gcs.parse_error_code(["10", "2"], device=DEVICE)


def test_error_codes_carry_pi_meanings() -> None:
    assert error_meaning(10) == "Controller was stopped by command"
    assert GCS_ERRORS[7] == "Position out of limits"
    error = GcsError(5, device="hexapod", command="MOV X 1")
    assert error.code == 5 and "servo off" in str(error) and "MOV X 1" in str(error)
    assert "unlisted" in error_meaning(-99)
