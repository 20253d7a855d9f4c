"""MDT693B protocol: encoding, reply framing and parsing, pure functions only."""

from __future__ import annotations

import math

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers import ProtocolError
from wavestack.drivers.mdt693b.protocol import (
    MAX_REPLY_BYTES,
    PROMPTS,
    DeviceIdentity,
    Reply,
    encode_command,
    encode_query,
    encode_set_voltage,
    parse_id,
    parse_number,
    parse_vlimit,
    split_reply,
)

# The id? reply of an MDT693B with firmware 1.10, as published in a session log (echo off).
ID_FW110 = (b"Model MDT693B Piezo Control Module\rFirmware Version: 1.10\rVoltage Range: 0V to 150V\r"
            b"Serial#:150226175403\rFriendly Name:MDT693B\rThorlabs, Inc. Newton, NJ 07860\rwww.thorlabs.com\r\r>")


# ----------------------------------------------------------------------------------- encoding
def test_encode_command_appends_cr() -> None:
    assert encode_command("vlimit?") == b"vlimit?\r"
    assert encode_query("y", "max") == b"ymax?\r"


def test_encode_set_voltage_uses_two_decimals() -> None:
    assert encode_set_voltage("x", 12.3456) == b"xvoltage=12.35\r"
    assert encode_set_voltage("z", 0) == b"zvoltage=0.00\r"


@pytest.mark.parametrize("command", ["", "x>y", "id?\r", "echo=1*", "ß?", "bang!"])
def test_encode_command_rejects_reserved_or_non_ascii(command: str) -> None:
    with pytest.raises(ValueError):
        encode_command(command)


@pytest.mark.parametrize(("axis", "volts"), [("w", 1.0), ("x", math.nan), ("x", -1.0), ("x", math.inf), ("x", True)])
def test_encode_set_voltage_rejects_bad_arguments(axis: str, volts: float) -> None:
    with pytest.raises(ValueError):
        encode_set_voltage(axis, volts)


def test_encode_query_rejects_unknown_quantity() -> None:
    with pytest.raises(ValueError):
        encode_query("x", "current")


# ------------------------------------------------------------------------------------ framing
@pytest.mark.parametrize(
    ("stream", "echo_of", "expect_body", "body", "prompt"),
    [
        (b"[  12.34]\r>", None, True, "[  12.34]", ">"),
        (b"xvoltage?\r[  12.34]\r>", b"xvoltage?", True, "[  12.34]", ">"),
        (b">", None, False, "", ">"),
        (b"xvoltage=1.00\r*", b"xvoltage=1.00", False, "", "*"),
        # firmware 1.05 prints its prompt before a query's reply as well as after it
        (b"vlimit?\r*[ 100]\r*", b"vlimit?", True, "[ 100]", "*"),
        (b"CMD_NOT_DEFINED>", None, True, "CMD_NOT_DEFINED", ">"),
        (b"serial?\r!", b"serial?", True, "", "!"),
    ],
)
def test_split_reply_variants(stream: bytes, echo_of: bytes | None, expect_body: bool, body: str, prompt: str) -> None:
    reply, rest = split_reply(stream + b"tail", echo_of=echo_of, expect_body=expect_body)
    assert reply == Reply(body, prompt)
    assert rest == b"tail"


def test_split_reply_id_keeps_lines() -> None:
    reply, rest = split_reply(ID_FW110, echo_of=None, expect_body=True)
    assert reply is not None and rest == b""
    assert reply.body.split("\r")[:2] == ["Model MDT693B Piezo Control Module", "Firmware Version: 1.10"]


def test_split_reply_waits_for_every_byte() -> None:
    stream = b"xvoltage?\r[  12.34]\r>"
    for cut in range(len(stream)):  # every strict prefix is incomplete
        assert split_reply(stream[:cut], echo_of=b"xvoltage?", expect_body=True) == (None, stream[:cut])
    assert split_reply(stream, echo_of=b"xvoltage?", expect_body=True)[0] == Reply("[  12.34]", ">")


def test_error_property() -> None:
    assert Reply("CMD_NOT_DEFINED", ">").error == "CMD_NOT_DEFINED"
    assert Reply("CMD_ARG_INVALID", "*").error == "CMD_ARG_INVALID"
    assert Reply("", "!").error == "!"
    assert Reply("[ 1.0]", ">").error is None


def test_split_reply_rejects_wrong_echo() -> None:
    with pytest.raises(ProtocolError, match="echo"):
        split_reply(b"yvoltage?\r[ 1]\r>", echo_of=b"xvoltage?", expect_body=True)


def test_split_reply_rejects_non_ascii_body() -> None:
    with pytest.raises(ProtocolError, match="printable ASCII"):
        split_reply(b"\x93\xfe\x01>", echo_of=None, expect_body=True)


def test_split_reply_gives_up_on_a_flood_without_prompt() -> None:
    flood = b"a" * (MAX_REPLY_BYTES + 1)
    with pytest.raises(ProtocolError, match="no prompt"):
        split_reply(flood, echo_of=None, expect_body=True)


def test_split_reply_honours_the_detected_prompt() -> None:
    # with the prompt known to be '>', a '*' is body text
    reply, _ = split_reply(b"a*b\r>", echo_of=None, expect_body=True, prompts=b">")
    assert reply == Reply("a*b", ">")


# ------------------------------------------------------------------------------------ parsing
@pytest.mark.parametrize(("body", "value"), [("[  12.34]", 12.34), ("[ 100]", 100.0), ("150.5", 150.5),
                                             ("0", 0.0), ("[-0.5]", -0.5), (" [ .25 ] ", 0.25),
                                             ("1e3", 1000.0)])  # a bare %g number (firmware 1.05)
def test_parse_number(body: str, value: float) -> None:
    assert parse_number(body) == value


@pytest.mark.parametrize("body", ["", "[]", "[ 1", "1]", "abc", "[1,2]", "nan", "inf", "1e", "1e999", "[[1]]", "1" * 400])
def test_parse_number_rejects(body: str) -> None:
    with pytest.raises(ProtocolError):
        parse_number(body)


@pytest.mark.parametrize(("body", "volts"), [("[  75]", 75.0), ("[ 100]", 100.0), ("[ 150]", 150.0),
                                             ("0", 75.0), ("1", 100.0), ("2", 150.0)])
def test_parse_vlimit_voltage_or_switch_position(body: str, volts: float) -> None:
    assert parse_vlimit(body) == volts


@pytest.mark.parametrize("body", ["[ 120]", "3", "[-1]"])
def test_parse_vlimit_rejects_other_settings(body: str) -> None:
    with pytest.raises(ProtocolError, match="75, 100 or 150"):
        parse_vlimit(body)


def test_parse_id_firmware_110() -> None:
    reply, _ = split_reply(ID_FW110, echo_of=None, expect_body=True)
    assert reply is not None
    identity = parse_id(reply.body)
    assert identity == DeviceIdentity("MDT693B", "1.10", "0V to 150V", "150226175403", "MDT693B", reply.body)
    assert identity.axes == ("x", "y", "z")


def test_parse_id_short_reply_of_a_single_axis_model() -> None:
    identity = parse_id("Model MDT694B Piezo Control Module\rFirmware Version: 1.05")
    assert (identity.model, identity.firmware, identity.serial_number) == ("MDT694B", "1.05", "")
    assert identity.axes == ("x",)


def test_parse_id_without_model_line() -> None:
    with pytest.raises(ProtocolError, match="Model"):
        parse_id("Firmware Version: 1.10")


# ------------------------------------------------------------------------------- properties
@fuzz_settings(300)
@given(data=st.binary(max_size=200), echo=st.sampled_from([None, b"xvoltage?", b"id?"]),
       expect_body=st.booleans(), prompts=st.sampled_from([PROMPTS, b">", b"*"]))
def test_split_reply_on_arbitrary_bytes(data: bytes, echo: bytes | None, expect_body: bool, prompts: bytes) -> None:
    try:
        reply, rest = split_reply(data, echo_of=echo, expect_body=expect_body, prompts=prompts)
    except ProtocolError:
        return
    if reply is None:
        assert rest == data
        return
    assert reply.prompt in (prompts + b"!").decode()
    assert data.endswith(rest) and len(rest) < len(data)
    assert all(32 <= ord(c) < 127 or c in "\r\n\t" for c in reply.body)
    for parse in (parse_number, parse_vlimit, parse_id):  # what a framed reply goes on to
        try:
            parse(reply.body)
        except ProtocolError:
            pass


@fuzz_settings(300)
@given(text=st.text(max_size=60) | st.from_regex(r"\[ *-?[0-9]{1,4}(\.[0-9]{0,3})?\]", fullmatch=True))
def test_parsers_on_arbitrary_text(text: str) -> None:
    for parse in (parse_number, parse_vlimit):
        try:
            value = parse(text)
        except ProtocolError:
            continue
        assert math.isfinite(value)
    try:
        identity = parse_id(text)
    except ProtocolError:
        return
    assert identity.model and identity.raw == text


@fuzz_settings(200)
@given(volts=st.floats(min_value=0.0, max_value=150.0, allow_nan=False))
def test_set_voltage_encoding_round_trips_within_the_wire_resolution(volts: float) -> None:
    wire = encode_set_voltage("x", volts)
    sent = float(wire.decode("ascii").split("=")[1])
    # two decimals on the wire: the sent value is within half a hundredth (plus float slack)
    assert abs(sent - volts) <= 0.005 + 1e-9
    assert parse_number(f"[{sent:8.2f}]") == pytest.approx(sent, abs=1e-12)
