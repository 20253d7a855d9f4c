"""Property tests of the simulated MDT693B's command parser (what the host sends, both command sets).

The simulator reads a byte stream of CR-terminated lines; whatever arrives, it must answer without
raising and run a command only as written: a line it cannot hold whole is refused, never executed
cut short.
"""

from __future__ import annotations

from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.mdt693b.protocol import encode_command
from wavestack.simulators.mdt693b.device import MDT693BDevice
from wavestack.simulators.mdt693b.personality import MDT693BPersonality

MODELS = st.sampled_from(["MDT693B", "MDT694B", "MDT693A"])


def _device(model: str, echo: bool, compatibility: bool = False) -> MDT693BDevice:
    personality = MDT693BPersonality(model=model, echo=echo, compatibility_mode=compatibility)  # type: ignore[arg-type]
    return MDT693BDevice(personality)


@fuzz_settings(300)
@given(data=st.binary(max_size=400), model=MODELS, echo=st.booleans(), compatibility=st.booleans())
def test_the_simulator_answers_any_bytes_without_raising(data: bytes, model: str, echo: bool,
                                                        compatibility: bool) -> None:
    device = _device(model, echo, compatibility)
    answer = device.feed(data)
    assert isinstance(answer, bytes)
    assert all(0.0 <= device.voltage(axis) <= 150.0 for axis in device.personality.axes)
    assert len(device.commands) == data.count(b"\r")  # one command per CR, partial lines kept


@fuzz_settings(300)
@given(zeros=st.integers(0, 400), volts=st.integers(1, 300), compat=st.booleans())
def test_a_setpoint_runs_as_written_or_not_at_all(zeros: int, volts: int, compat: bool) -> None:
    """``xvoltage=`` followed by any number of leading zeros: the value written, or a refusal."""
    model = "MDT693A" if compat else "MDT693B"
    device = _device(model, echo=False)
    command = ("XV" if compat else "xvoltage=") + "0" * zeros + str(volts)
    answer = device.feed(encode_command(command))
    if device.voltage("x") == 0.0:  # refused: said so, with the set's error
        assert answer in ((b"!",) if compat else (b"CMD_NOT_DEFINED>", b"CMD_ARG_INVALID>"))
    else:
        assert device.voltage("x") == float(volts) and answer in (b"*", b">")
    if volts > 150:  # beyond the 0..150 V the command takes: refused, not clipped
        assert device.voltage("x") == 0.0


def test_an_over_long_line_is_refused_not_run_cut_short() -> None:
    # regression: the line buffer kept the first 256 bytes and ran them, so 'xvoltage=000...07'
    # (a valid number) set 0 V
    device = _device("MDT693B", echo=False)
    assert device.feed(b"xvoltage=5\r") == b">"
    assert device.feed(b"xvoltage=" + b"0" * 260 + b"7\r") == b"CMD_NOT_DEFINED>"
    assert device.voltage("x") == 5.0
    assert device.feed(b"xvoltage=6\r") == b">" and device.voltage("x") == 6.0  # the next line is whole again
