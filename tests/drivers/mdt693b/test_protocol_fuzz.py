"""Property tests of the MDT693B / MDT694B / MDT693A ASCII protocol, driver against simulator.

What is parsed, host side: the reply stream (:func:`split_reply`) and the reply bodies
(:func:`parse_number`, :func:`parse_vlimit`, :func:`parse_id`, :func:`parse_compatibility_mode`).
Device side: the simulator's command parser (:class:`MDT693BDevice.feed`, both command sets). Every
host parser returns a value or raises :class:`ProtocolError`; the simulator answers any bytes without
raising; what the driver encodes, the simulator executes as meant, and what the simulator answers,
the driver reads back as the simulator's state.
"""

from __future__ import annotations

import math

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.errors import LimitError, ProtocolError
from wavestack.drivers.mdt693b.command_sets import (A_COMMANDS, B_COMMANDS, command_set_after_probe,
                                                    parse_compatibility_mode)
from wavestack.drivers.mdt693b.limits import _effective_limits, _on_wire
from wavestack.drivers.mdt693b.protocol import (encode_command, encode_query, encode_set_voltage, parse_id,
                                                parse_number, parse_vlimit, split_reply)
from wavestack.simulators.mdt693b.device import MDT693BDevice
from wavestack.simulators.mdt693b.personality import MDT693BPersonality

PRINTABLE = st.characters(min_codepoint=32, max_codepoint=126)


def _mutations(valid: bytes) -> st.SearchStrategy[bytes]:
    """Truncations, single-byte changes and trailing garbage of a valid message."""
    cut = st.integers(0, len(valid)).map(lambda n: valid[:n])
    flip = st.tuples(st.integers(0, max(len(valid) - 1, 0)), st.integers(0, 255)).map(
        lambda p: valid[:p[0]] + bytes([p[1]]) + valid[p[0] + 1:])
    extra = st.binary(min_size=1, max_size=8).map(lambda tail: valid + tail)
    return st.one_of(cut, flip, extra)


VALID_REPLIES = [b"xvoltage?\r[  12.34]\r>", b"[  12.34]\r>", b">", b"*[ 100]\r*", b"CMD_NOT_DEFINED>", b"!",
                 b"xr?\r*[  12.3]\r*", b"Model MDT693B Piezo Control Module\rFirmware Version: 1.10\r>"]
replies = st.one_of(st.binary(max_size=80), st.sampled_from(VALID_REPLIES).flatmap(_mutations))
echoes = st.sampled_from([None, b"xvoltage?", b"XR?", b"id?"])


# ---------------------------------------------------------------------------------------------- (a)
@fuzz_settings(300)
@given(stream=replies, echo=echoes, expect_body=st.booleans(), optional=st.booleans(),
       prompts=st.sampled_from([b">*", b">", b"*"]))
def test_split_reply_is_consistent_on_every_prefix_of_any_stream(stream: bytes, echo: bytes | None, expect_body: bool,
                                                                 optional: bool, prompts: bytes) -> None:
    """Bytes arrive in any pieces: each prefix gives "need more" or the same reply as the whole."""
    first = None
    for end in range(len(stream) + 1):
        try:
            reply, rest = split_reply(stream[:end], echo_of=echo, expect_body=expect_body, prompts=prompts,
                                      echo_optional=optional)
        except ProtocolError:
            return  # the stream is refused from here on; the driver resynchronises
        if reply is None:
            assert first is None and rest == stream[:end]
            continue
        assert reply.body.isascii() and reply.prompt in ">*!"
        if first is None:
            first = (reply, end - len(rest))
        assert (reply, end - len(rest)) == first  # more bytes never change a reply already cut


@fuzz_settings(300)
@given(text=st.one_of(st.text(max_size=40), st.text(PRINTABLE, max_size=40),
                      st.sampled_from(["[  12.34]", "150", "1e-05", "[ 100]", "[MDT693A Compatibility Mode On]",
                                       "Model MDT694B\rSerial#:1"]).map(str.encode).flatmap(_mutations).map(
                          lambda b: b.decode("latin-1"))))
def test_reply_body_parsers_return_or_raise_protocol_error(text: str) -> None:
    for parse in (parse_number, parse_vlimit, parse_id, parse_compatibility_mode):
        try:
            value = parse(text)
        except ProtocolError:
            continue
        if parse is parse_number:
            assert math.isfinite(value)  # type: ignore[arg-type]
        if parse is parse_vlimit:
            assert value in (75.0, 100.0, 150.0)


@fuzz_settings(300)
@given(command=st.one_of(st.text(max_size=20), st.text(PRINTABLE, max_size=20).map(lambda t: t + "\n"),
                         st.sampled_from(["id?", "xvoltage=1.5", "%", "XV12.3"]).flatmap(
                             lambda t: st.tuples(st.integers(0, len(t)), st.characters()).map(
                                 lambda p: t[:p[0]] + p[1] + t[p[0]:]))))
def test_an_encoded_command_is_one_line_of_printable_ascii(command: str) -> None:
    try:
        line = encode_command(command)
    except ValueError:
        return
    body = line[:-1]
    assert line.endswith(b"\r") and body.decode("ascii") == command
    assert all(32 <= byte < 127 for byte in body) and not any(c in body for c in b">*!%"[:3])
    assert b"%" not in body[1:]


def test_a_command_ending_in_a_line_feed_is_refused() -> None:
    # regression: the pattern was applied with re.match, whose "$" also matches before a final "\n",
    # so "id?\n" went out as b"id?\n\r"
    with pytest.raises(ValueError, match="not an MDT693B command"):
        encode_command("id?\n")


@fuzz_settings(300)
@given(probe=replies, compatibility=st.one_of(st.none(), replies))
def test_the_command_set_probe_decides_or_asks_or_raises_protocol_error(probe: bytes,
                                                                       compatibility: bytes | None) -> None:
    """Any answers to ``echo=0`` and ``cm?``: a command set, None (ask ``cm?``) or ProtocolError."""
    try:
        probe_reply = split_reply(probe, echo_of=None, expect_body=False)[0]
        cm_reply = None if compatibility is None else split_reply(compatibility, echo_of=None, expect_body=True)[0]
    except ProtocolError:
        return
    if probe_reply is None:
        return
    try:
        decided = command_set_after_probe(probe_reply, cm_reply)
    except ProtocolError:
        assert cm_reply is not None and probe_reply.prompt == "*"
        return
    assert decided in ("mdt693b", "mdt693a") or (decided is None and cm_reply is None and probe_reply.prompt == "*")


# ---------------------------------------------------------------------------------------------- (b)
@fuzz_settings(300)
@given(value=st.floats(-1e12, 1e12), width=st.integers(0, 10), decimals=st.integers(0, 4))
def test_bracketed_numbers_round_trip(value: float, width: int, decimals: int) -> None:
    text = f"{value:{width}.{decimals}f}"
    assert parse_number(f"[{text}]") == float(text)
    assert parse_number(text) == float(text)


@fuzz_settings(300)
@given(value=st.one_of(st.floats(0.0, 150.0), st.floats(-1e300, 1e300), st.sampled_from([1e-5, 1.5e-7, 0.0])))
def test_bare_numbers_as_printf_g_writes_them_round_trip(value: float) -> None:
    """Firmware 1.05 answers ``xmin?`` with a bare ``%g`` number, which has an exponent for small values."""
    text = f"{value:g}"
    assert parse_number(text) == float(text)


def test_a_bare_number_with_an_exponent_is_read() -> None:
    # regression: the simulator answers `xmin?` with "1e-05" after `xmin=0.00001` (%g, as the bare
    # "150" of firmware 1.05 suggests); the driver refused it as "not a number"
    assert parse_number("1e-05") == 1e-05
    assert parse_number("[ 1.5E+02]") == 150.0
    for bad in ("1e", "e5", "1e999", "1e+", "1.2.3"):
        with pytest.raises(ProtocolError):
            parse_number(bad)


# ---------------------------------------------------------------------------------------------- (c)
def _device(**personality: object) -> MDT693BDevice:
    return MDT693BDevice(MDT693BPersonality(**personality))  # type: ignore[arg-type]


def _exchange(device: MDT693BDevice, sent: bytes, *, expect_body: bool, compat: bool = False) -> str:
    """What the driver reads from the simulator's answer to ``sent``: the reply body."""
    answer = device.feed(sent)
    echo = sent.rstrip(b"\r") if device.echo or compat else None
    reply, rest = split_reply(answer, echo_of=echo, expect_body=expect_body, echo_optional=compat)
    assert reply is not None and rest == b"" and reply.error is None, answer
    return reply.body


volts = st.one_of(st.floats(0.0, 150.0), st.sampled_from([0.0, 0.004, 0.005, 149.995, 150.0]))


@fuzz_settings(200)
@given(axis=st.sampled_from("xyz"), value=volts, echo=st.booleans(), prompt=st.sampled_from([">", "*"]))
def test_a_setpoint_the_driver_encodes_is_the_voltage_the_simulator_sets_and_reads_back(
        axis: str, value: float, echo: bool, prompt: str) -> None:
    device = _device(echo=echo, prompt=prompt, decimals=2)
    wire = round(value, 2)  # the driver sends two decimals
    assert _exchange(device, encode_set_voltage(axis, value), expect_body=False) == ""
    assert device.voltage(axis) == pytest.approx(wire, abs=1e-9)
    body = _exchange(device, encode_query(axis, "voltage"), expect_body=True)
    assert parse_number(body) == pytest.approx(wire, abs=0.005 + 1e-9)  # the reply has two decimals


@fuzz_settings(200)
@given(axis=st.sampled_from("xyz"), value=volts, echo=st.booleans())
def test_the_mdt693a_set_agrees_the_same_way(axis: str, value: float, echo: bool) -> None:
    device = _device(model="MDT693A", echo=echo)
    assert _exchange(device, A_COMMANDS.set_voltage(axis, value), expect_body=False, compat=True) == ""
    assert device.voltage(axis) == pytest.approx(round(value, 2), abs=1e-9)
    body = _exchange(device, encode_command(A_COMMANDS.voltage_query(axis)), expect_body=True, compat=True)
    assert parse_number(body) == pytest.approx(round(value, 2), abs=0.05 + 1e-9)  # one decimal in the A set


@fuzz_settings(200)
@given(axis=st.sampled_from("xyz"), low=st.one_of(st.floats(0.0, 150.0), st.sampled_from([1e-5, 1e-4, 0.0])),
       high=st.floats(0.0, 150.0), prompt=st.sampled_from([">", "*"]))
def test_axis_limits_the_simulator_reports_read_back_in_the_driver(axis: str, low: float, high: float,
                                                                   prompt: str) -> None:
    device = _device(echo=False, prompt=prompt)
    low, high = min(low, high), max(low, high)
    device.set_axis_limits(axis, low, high)
    for quantity, value in (("min", low), ("max", high)):
        body = _exchange(device, encode_query(axis, quantity), expect_body=True)
        assert parse_number(body) == pytest.approx(value, rel=1e-5, abs=1e-12)  # %g keeps 6 digits
    assert parse_vlimit(_exchange(device, encode_command(B_COMMANDS.vlimit_query), expect_body=True)) == 150.0


@fuzz_settings(300)
@given(command=st.text(PRINTABLE, min_size=1, max_size=40).filter(lambda c: not c.strip().lower().startswith(
    ("cm=", "echo=", "e"))), echo=st.booleans(), model=st.sampled_from(["MDT693B", "MDT694B"]))
def test_every_simulator_answer_to_a_command_line_is_one_reply_the_driver_cuts(command: str, echo: bool,
                                                                              model: str) -> None:
    """Firmware 1.10 (prompt ``>``): whatever the line, exactly one reply comes back, nothing after it."""
    device = _device(model=model, echo=echo)
    line = command.encode("ascii")
    answer = device.feed(line + b"\r")
    reply, rest = split_reply(answer, echo_of=line if echo else None, expect_body=False, prompts=b">")
    assert reply is not None and rest == b"", answer


# ------------------------------------------------------------------ limits: what goes on the wire
limit_volts = st.one_of(st.floats(0.0, 150.0), st.integers(0, 15000).map(lambda c: c / 100),
                        st.integers(0, 150000).map(lambda m: m / 1000))


@fuzz_settings(300)
@given(device_min=limit_volts, device_max=limit_volts, software=st.tuples(limit_volts, limit_volts),
       vlimit=st.sampled_from([75.0, 100.0, 150.0]), fraction=st.floats(0.0, 1.0))
def test_a_setpoint_inside_the_limits_goes_on_the_wire_inside_them(device_min: float, device_max: float,
                                                                   software: tuple[float, float], vlimit: float,
                                                                   fraction: float) -> None:
    """Limits read from the device (``xmin?``, ``xmax?``, ``vlimit?``): the two-decimal wire value stays inside."""
    try:
        limits = _effective_limits("MDT693B", "x", software_min_v=min(software), software_max_v=max(software),
                                   device_min_v=device_min, device_max_v=device_max, vlimit_v=vlimit)
    except LimitError:
        return
    requested = limits.min_v + fraction * (limits.max_v - limits.min_v)
    for volts in (requested, limits.min_v, limits.max_v):
        wire = _on_wire(volts, limits)
        assert limits.min_v <= wire <= limits.max_v
        assert encode_set_voltage("x", wire) == f"xvoltage={wire:.2f}\r".encode()
        assert float(f"{wire:.2f}") == wire  # what the controller parses is exactly the value checked
        assert abs(wire - volts) <= 0.01 + 1e-9


def test_a_range_narrower_than_the_wire_resolution_is_refused() -> None:
    # regression: device limits [12.343, 12.347] V hold no two-decimal voltage; a setpoint of 12.345 V
    # went out as 12.35 V (or 12.34 V), outside the limits the driver had just checked
    with pytest.raises(LimitError, match="two-decimal"):
        _effective_limits("MDT693B", "x", software_min_v=0.0, software_max_v=150.0, device_min_v=12.343,
                          device_max_v=12.347, vlimit_v=150.0)
