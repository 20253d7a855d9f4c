"""The driver with a controller that speaks the MDT693A command set: detected, configured, switched."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest

from wavestack.drivers import LimitError, ProtocolError
from wavestack.drivers.mdt693b import MDT693B
from wavestack.simulators.mdt693b import MDT693BDevice, MDT693BPersonality

# the MDT693A set reads a voltage back with one decimal: within half of it of the commanded value
READBACK_RESOLUTION_V = 0.05 + 1e-9
B_COMMANDS = {"echo=0", "id?", "vlimit?", "xmin?", "xmax?", "xvoltage?", "cm?"}

Connect = Callable[[MDT693BDevice], str]  # the `connect` fixture (conftest.py)


@contextmanager
def opened(url: str, **options: object) -> Iterator[MDT693B]:
    with MDT693B(url, **options) as piezo:  # type: ignore[arg-type]
        yield piezo


PERSONALITIES = {
    "b-in-a-mode-echo": MDT693BPersonality(echo=True, compatibility_mode=True),
    "b-in-a-mode-quiet": MDT693BPersonality(echo=False, compatibility_mode=True),
    "mdt693a": MDT693BPersonality(model="MDT693A", firmware="3.01", echo=True),
}


@pytest.mark.parametrize("personality", PERSONALITIES.values(), ids=PERSONALITIES.keys())
@pytest.mark.parametrize("command_set", ["auto", "mdt693a"])
def test_set_voltage_reads_back_in_the_mdt693a_set(connect: Connect, personality: MDT693BPersonality,
                                                   command_set: str) -> None:
    device = MDT693BDevice(personality)
    with opened(connect(device), axes=("x", "y", "z"), command_set=command_set) as piezo:
        assert piezo.command_set == "mdt693a"
        assert piezo.identity.model == personality.model
        assert piezo.identity.firmware == personality.firmware
        for axis, volts in (("x", 12.34), ("z", 99.9), ("y", 0.0)):
            reading = piezo.set_voltage(axis, volts, timeout_s=1.0)
            assert device.voltage(axis) == pytest.approx(reading.commanded_v, abs=1e-9)
            assert abs(reading.readback_v - reading.commanded_v) <= READBACK_RESOLUTION_V
            assert piezo.read_voltage(axis, timeout_s=1.0) == reading.readback_v
        assert device.compatibility_mode is True  # the driver never switches the mode on its own
        sent = set(device.commands)
        assert "XV12.34" in sent and "XR?" in sent and "I" in sent
        # configured for the A set, not a single B command reaches the wire
        if command_set == "mdt693a":
            assert not sent & B_COMMANDS


def test_limits_come_from_the_limit_switch_and_xl_xh(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=False, compatibility_mode=True, vlimit_v=100.0))
    device.set_axis_limits("x", 5.0, 90.0)
    with opened(connect(device), axes=("x",), software_max_v=140.0) as piezo:
        limits = piezo.limits("x")
        assert (limits.min_v, limits.max_v, limits.vlimit_v) == (5.0, 90.0, 100.0)
        assert {"%", "XL?", "XH?"} <= set(device.commands)
        with pytest.raises(LimitError):
            piezo.set_voltage("x", 95.0, timeout_s=1.0)
        assert device.voltage("x") == 0.0
        assert piezo.set_voltage("x", 95.0, timeout_s=1.0, clamp=True).commanded_v == 90.0


def test_readback_mismatch_in_the_mdt693a_set_reads_the_limits_again(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=False, compatibility_mode=True))
    with opened(connect(device), axes=("x",)) as piezo:
        device.vlimit_v = 75.0
        with pytest.raises(ProtocolError, match="reads back 75"):
            piezo.set_voltage("x", 120.0, timeout_s=1.0)
        assert piezo.limits("x").max_v == 75.0


def test_switching_modes_keeps_the_driver_working(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=True))
    with opened(connect(device), axes=("x", "y")) as piezo:
        assert piezo.command_set == "mdt693b"
        piezo.set_voltage("x", 10.0, timeout_s=1.0)
        piezo.set_compatibility_mode(True, timeout_s=1.0)
        assert device.compatibility_mode is True and piezo.command_set == "mdt693a"
        assert piezo.read_voltage("x", timeout_s=1.0) == 10.0
        piezo.set_voltage("y", 33.3, timeout_s=1.0)
        assert device.commands[-1] == "YR?" and device.voltage("y") == pytest.approx(33.3)
        piezo.set_compatibility_mode(False, timeout_s=1.0)
        assert device.compatibility_mode is False and piezo.command_set == "mdt693b"
        assert piezo.set_voltage("y", 44.44, timeout_s=1.0).readback_v == 44.44
    # the mode is the controller's: the next open finds it as it was left
    with opened(connect(MDT693BDevice(MDT693BPersonality(compatibility_mode=True))), axes=("x",)) as piezo:
        assert piezo.command_set == "mdt693a"


def test_mdt693a_refuses_the_compatibility_switch(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(model="MDT693A", firmware="3.01", echo=False))
    with opened(connect(device), axes=("x",)) as piezo:
        with pytest.raises(ProtocolError, match="cm=0"):
            piezo.set_compatibility_mode(False, timeout_s=1.0)
        assert piezo.set_voltage("x", 5.0, timeout_s=1.0).readback_v == 5.0  # resynchronised, still usable


def test_configured_b_set_names_the_compatibility_mode(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=False, compatibility_mode=True))
    with pytest.raises(ProtocolError, match="compatibility mode"):
        with opened(connect(device), axes=("x",), command_set="mdt693b"):
            pass
    with pytest.raises(ProtocolError, match="CMD_NOT_DEFINED"):  # and the reverse
        with opened(connect(MDT693BDevice(MDT693BPersonality(echo=False))), axes=("x",), command_set="mdt693a"):
            pass


def test_command_set_option_is_checked() -> None:
    with pytest.raises(ValueError, match="command_set"):
        MDT693B("sim://mdt693b", command_set="mdt693c")
