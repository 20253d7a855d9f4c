"""The two command sets and the compatibility-mode replies, pure functions only."""

from __future__ import annotations

import math

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers import ProtocolError
from wavestack.drivers.mdt693b.command_sets import (
    A_COMMANDS,
    B_COMMANDS,
    command_set_after_probe,
    encode_compatibility_mode,
    parse_compatibility_mode,
)
from wavestack.drivers.mdt693b.protocol import Reply, encode_command, split_reply


def test_each_set_spells_the_same_operations() -> None:
    assert [B_COMMANDS.voltage_query("x"), B_COMMANDS.min_query("y"), B_COMMANDS.max_query("z")] == \
        ["xvoltage?", "ymin?", "zmax?"]
    assert [A_COMMANDS.voltage_query("x"), A_COMMANDS.min_query("y"), A_COMMANDS.max_query("z")] == \
        ["XR?", "YL?", "ZH?"]
    assert (B_COMMANDS.id_query, B_COMMANDS.vlimit_query) == ("id?", "vlimit?")
    assert (A_COMMANDS.id_query, A_COMMANDS.vlimit_query) == ("I", "%")
    assert A_COMMANDS.set_voltage("z", 0) == b"ZV0.00\r"
    assert encode_command("%") == b"%\r"
    assert encode_compatibility_mode(False) == b"cm=0\r"


@pytest.mark.parametrize(("axis", "volts"), [("w", 1.0), ("x", math.nan), ("x", -0.5)])
def test_a_set_refuses_what_the_b_set_refuses(axis: str, volts: float) -> None:
    with pytest.raises(ValueError):
        A_COMMANDS.set_voltage(axis, volts)
    with pytest.raises(ValueError):
        A_COMMANDS.voltage_query("w")


@pytest.mark.parametrize(("body", "on"), [
    ("[MDT693A Compatibility Mode Off]", False), ("[MDT693A Compatibility Mode On]", True),
    ("[MDT694A Compatibility Mode On]", True), ("1", True), ("[0]", False), (" 0 ", False),
])
def test_parse_compatibility_mode(body: str, on: bool) -> None:
    assert parse_compatibility_mode(body) is on


@pytest.mark.parametrize("body", ["", "[MDT693A Compatibility Mode]", "2", "On Off", "CMD_NOT_DEFINED"])
def test_parse_compatibility_mode_refuses_anything_else(body: str) -> None:
    with pytest.raises(ProtocolError):
        parse_compatibility_mode(body)


def test_command_set_after_probe() -> None:
    assert command_set_after_probe(Reply("", ">"), None) == "mdt693b"
    assert command_set_after_probe(Reply("", "!"), None) == "mdt693a"
    star = Reply("", "*")
    assert command_set_after_probe(star, None) is None  # ask cm? first
    assert command_set_after_probe(star, Reply("[MDT693A Compatibility Mode On]", "*")) == "mdt693a"
    assert command_set_after_probe(star, Reply("[MDT693A Compatibility Mode Off]", "*")) == "mdt693b"
    assert command_set_after_probe(star, Reply("CMD_NOT_DEFINED", "*")) == "mdt693b"


@pytest.mark.parametrize(("received", "body"), [
    (b"*[  12.3]\r*", "[  12.3]"),                 # echo off
    (b"xr?\r*[  12.3]\r*", "[  12.3]"),            # echo on, lower case as the MDT693A sends it
    (b"XR?\r*[  12.3]\r*", "[  12.3]"),
])
def test_optional_echo_is_skipped_without_regard_to_case(received: bytes, body: str) -> None:
    reply, rest = split_reply(received, echo_of=b"XR?", expect_body=True, prompts=b"*", echo_optional=True)
    assert reply == Reply(body, "*") and rest == b""


@fuzz_settings(100)
@given(st.integers(min_value=0, max_value=15), st.booleans())
def test_optional_echo_in_any_two_pieces(cut: int, echo: bool) -> None:
    received = (b"xv1.25\r" if echo else b"") + b"*"
    first, _ = split_reply(received[:cut], echo_of=b"XV1.25", expect_body=False, prompts=b"*", echo_optional=True)
    whole, _ = split_reply(received, echo_of=b"XV1.25", expect_body=False, prompts=b"*", echo_optional=True)
    assert whole == Reply("", "*")
    assert first is None or cut >= len(received)
