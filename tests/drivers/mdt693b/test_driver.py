"""MDT693B driver against the simulated controller, over ``sim://`` and over a real pseudo-terminal."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest
import serial

from wavestack.drivers import DeviceDisconnected, DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.mdt693b import MDT693B
from wavestack.simulators.mdt693b import MDT693BDevice, MDT693BPersonality
from wavestack.simulators import attach_simulated_device

WIRE_RESOLUTION_V = 0.005  # the driver sends two decimals, so a set voltage is within half a hundredth
ECHO_GT = MDT693BPersonality(echo=True, prompt=">")
QUIET_STAR = MDT693BPersonality(echo=False, prompt="*", firmware="1.05", decimals=1)

Connect = Callable[[MDT693BDevice], str]  # the `connect` fixture (conftest.py)


@contextmanager
def opened(url: str, **options: object) -> Iterator[MDT693B]:
    piezo = MDT693B(url, **options)  # type: ignore[arg-type]
    piezo.open()
    try:
        yield piezo
    finally:
        piezo.close()


# ------------------------------------------------------------------------------ open, identity
@pytest.mark.parametrize("personality", [ECHO_GT, QUIET_STAR], ids=["echo-gt", "quiet-star"])
def test_open_reads_identity_and_switches_echo_off(connect: Connect, personality: MDT693BPersonality) -> None:
    device = MDT693BDevice(personality)
    with opened(connect(device), axes=("x", "y", "z")) as piezo:
        assert piezo.identity.model == "MDT693B"
        assert piezo.identity.firmware == personality.firmware
        assert piezo.vlimit_v == personality.vlimit_v
        assert device.echo is False
        # after a '*' prompt (firmware 1.05, or the MDT693A command set) cm? tells the command set
        asked = ("echo=0", "cm?", "id?", "vlimit?") if personality.prompt == "*" else ("echo=0", "id?", "vlimit?")
        assert device.commands[:len(asked)] == asked
        assert piezo.command_set == "mdt693b"


@pytest.mark.parametrize("personality", [ECHO_GT, QUIET_STAR], ids=["echo-gt", "quiet-star"])
def test_set_voltage_reads_back(connect: Connect, personality: MDT693BPersonality) -> None:
    device = MDT693BDevice(personality)
    with opened(connect(device), axes=("x", "z")) as piezo:
        for axis, volts in (("x", 12.345), ("z", 99.9), ("x", 0.0)):
            reading = piezo.set_voltage(axis, volts, timeout_s=1.0)
            assert reading.axis == axis and reading.requested_v == volts and not reading.clamped
            assert abs(reading.commanded_v - volts) <= WIRE_RESOLUTION_V
            assert device.voltage(axis) == pytest.approx(reading.commanded_v, abs=1e-9)
            # the reply shows `decimals` digits: read-back within half of the last digit
            assert abs(reading.readback_v - reading.commanded_v) <= 0.5 * 10.0 ** -personality.decimals + 1e-9
            assert piezo.read_voltage(axis, timeout_s=1.0) == reading.readback_v
        assert f"zvoltage={99.9:.2f}" in device.commands


def test_single_axis_model_refuses_other_axes(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(model="MDT694B"))
    piezo = MDT693B(connect(device), axes=("x", "y"))
    with pytest.raises(ProtocolError, match="MDT694B has only"):
        piezo.open()
    assert not piezo.is_open


# ------------------------------------------------------------------------------------ limits
@pytest.mark.parametrize("vlimit", [75.0, 100.0])
def test_limits_come_from_vlimit_axis_limits_and_software(connect: Connect, vlimit: float) -> None:
    device = MDT693BDevice(MDT693BPersonality(vlimit_v=vlimit))
    device.set_axis_limits("x", 5.0, 60.0)
    device.set_axis_limits("y", 0.0, 150.0)
    software = (2.0, 90.0)
    with opened(connect(device), axes=("x", "y"), software_min_v=software[0], software_max_v=software[1]) as piezo:
        for axis, (dev_min, dev_max) in {"x": (5.0, 60.0), "y": (0.0, 150.0)}.items():
            limits = piezo.limits(axis)
            assert limits.min_v == max(software[0], dev_min)
            assert limits.max_v == min(software[1], dev_max, vlimit)
            assert (limits.device_min_v, limits.device_max_v, limits.vlimit_v) == (dev_min, dev_max, vlimit)


@pytest.mark.parametrize("volts", [75.01, 140.0, 0.5])
def test_out_of_limit_setpoint_never_reaches_the_wire(connect: Connect, volts: float) -> None:
    device = MDT693BDevice(MDT693BPersonality(vlimit_v=75.0))
    device.set_axis_limits("x", 1.0, 150.0)
    with opened(connect(device)) as piezo:
        piezo.set_voltage("x", 10.0, timeout_s=1.0)
        before = device.received
        with pytest.raises(LimitError, match="nothing sent"):
            piezo.set_voltage("x", volts, timeout_s=1.0)
        assert device.received == before
        assert device.voltage("x") == 10.0


def test_clamp_sends_the_limit(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(vlimit_v=100.0))
    with opened(connect(device), software_max_v=80.0) as piezo:
        reading = piezo.set_voltage("x", 95.0, timeout_s=1.0, clamp=True)
        assert (reading.requested_v, reading.commanded_v, reading.clamped) == (95.0, 80.0, True)
        assert device.voltage("x") == 80.0


@pytest.mark.parametrize("volts", [float("nan"), float("inf")])
def test_non_finite_setpoint_is_a_value_error(connect: Connect, volts: float) -> None:
    device = MDT693BDevice()
    with opened(connect(device)) as piezo:
        before = device.received
        with pytest.raises(ValueError, match="finite"):
            piezo.set_voltage("x", volts, timeout_s=1.0, clamp=True)
        with pytest.raises(ValueError, match="configured"):
            piezo.set_voltage("y", 1.0, timeout_s=1.0)
        assert device.received == before


def test_readback_mismatch_after_the_limit_switch_turned(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(vlimit_v=150.0))
    with opened(connect(device)) as piezo:
        device.vlimit_v = 75.0  # someone turns the front-panel switch behind the driver's back
        with pytest.raises(ProtocolError, match="reads back 75"):
            piezo.set_voltage("x", 100.0, timeout_s=1.0)
        assert piezo.limits("x").max_v == 75.0  # limits read again after the mismatch
        with pytest.raises(LimitError):
            piezo.set_voltage("x", 100.0, timeout_s=1.0)


# ------------------------------------------------------------------------------------ faults
def test_silent_device_times_out_then_recovers(connect: Connect) -> None:
    device = MDT693BDevice()
    with opened(connect(device)) as piezo:
        piezo.set_voltage("x", 20.0, timeout_s=1.0)
        device.faults.silent = True
        with pytest.raises(DeviceTimeout, match="no complete reply"):
            piezo.read_voltage("x", timeout_s=0.2)
        with pytest.raises(DeviceTimeout):
            piezo.set_voltage("x", 30.0, timeout_s=0.2)
        device.faults.silent = False
        assert piezo.set_voltage("x", 30.0, timeout_s=1.0).readback_v == 30.0
        assert piezo.read_voltage("x", timeout_s=1.0) == 30.0


def test_garbage_is_a_protocol_error_then_recovers(connect: Connect) -> None:
    device = MDT693BDevice()
    with opened(connect(device)) as piezo:
        device.faults.garbage = True
        with pytest.raises(ProtocolError):
            piezo.read_voltage("x", timeout_s=0.5)
        with pytest.raises(ProtocolError):
            piezo.read_voltage("x", timeout_s=0.5)
        device.faults.garbage = False
        assert piezo.set_voltage("x", 42.0, timeout_s=1.0).readback_v == 42.0


def test_late_bytes_of_a_timed_out_reply_are_flushed_by_the_resync(connect: Connect) -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=False))
    with opened(connect(device)) as piezo:
        piezo.set_voltage("x", 12.5, timeout_s=1.0)
        device.faults.split_replies = True  # pieces 10 ms apart: the last one comes after a 5 ms deadline
        with pytest.raises(DeviceTimeout):
            piezo.read_voltage("x", timeout_s=0.005)
        # without the resync the tail of that reply ("...]\r>") would be read as the next reply
        assert piezo.read_voltage("x", timeout_s=1.0) == 12.5
        assert piezo.set_voltage("x", 13.0, timeout_s=1.0).readback_v == 13.0


@pytest.mark.parametrize("personality", [ECHO_GT, QUIET_STAR], ids=["echo-gt", "quiet-star"])
def test_split_replies_are_reassembled(connect: Connect, personality: MDT693BPersonality) -> None:
    device = MDT693BDevice(personality)
    device.faults.split_replies = True
    with opened(connect(device), axes=("x", "y")) as piezo:
        assert piezo.identity.model == "MDT693B"
        assert piezo.set_voltage("y", 33.3, timeout_s=1.0).readback_v == pytest.approx(33.3, abs=0.05)


def test_unplug_is_a_disconnect_that_sticks_until_reopen(connect: Connect, transport: str) -> None:
    device = MDT693BDevice()
    url = connect(device)
    piezo = MDT693B(url)
    piezo.open()
    try:
        piezo.set_voltage("x", 10.0, timeout_s=1.0)
        device.faults.unplugged = True
        with pytest.raises(DeviceDisconnected, match="connection failed"):
            piezo.read_voltage("x", timeout_s=1.0)
        assert not piezo.is_open
        with pytest.raises(DeviceDisconnected, match="lost earlier"):
            piezo.set_voltage("x", 11.0, timeout_s=1.0)
        if transport == "sim":  # a pty's master is gone for good; a USB port comes back
            with pytest.raises(DeviceDisconnected, match="cannot open"):
                piezo.open()
            device.faults.unplugged = False
            piezo.open()
            assert piezo.read_voltage("x", timeout_s=1.0) == 10.0
            assert piezo.set_voltage("x", 11.0, timeout_s=1.0).readback_v == 11.0
    finally:
        piezo.close()


def test_commands_are_serialised_across_threads(connect: Connect) -> None:
    device = MDT693BDevice()
    errors: list[BaseException] = []
    with opened(connect(device), axes=("x", "y", "z")) as piezo:
        def worker(axis: str, base: float) -> None:
            try:
                for step in range(15):
                    volts = base + step
                    assert piezo.set_voltage(axis, volts, timeout_s=2.0).readback_v == volts
            except BaseException as error:  # reported by the main thread
                errors.append(error)

        threads = [threading.Thread(target=worker, args=(axis, base)) for axis, base in
                   (("x", 10.0), ("y", 40.0), ("z", 70.0))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert errors == []
        assert [device.voltage(a) for a in "xyz"] == [24.0, 54.0, 84.0]


# ------------------------------------------------------------------------------- lifecycle
def test_calls_on_a_closed_driver_raise_disconnected() -> None:
    piezo = MDT693B("sim://mdt693b")
    with pytest.raises(DeviceDisconnected, match="not open"):
        piezo.read_voltage("x", timeout_s=0.1)
    with piezo:
        assert piezo.is_open
    with pytest.raises(DeviceDisconnected):
        piezo.limits("x")


def test_open_failures() -> None:
    with pytest.raises(DeviceDisconnected, match="cannot open"):
        MDT693B("sim://mdt693b/nobody").open()
    with pytest.raises(ValueError, match="register_serial_simulators"):
        MDT693B("nosuchscheme://x").open()
    with pytest.raises(ValueError):
        MDT693B("sim://mdt693b", software_min_v=50.0, software_max_v=40.0)
    with pytest.raises(ValueError):
        MDT693B("sim://mdt693b", axes=("x", "x"))


# --------------------------------------------------------------------- simulator, seen raw
def test_device_model_replies_like_the_firmware() -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=True, prompt=">"))
    assert device.feed(b"xvoltage=12.5\r") == b"xvoltage=12.5\r>"
    assert device.feed(b"xvolt") == b""  # nothing until the CR
    assert device.feed(b"age?\r") == b"xvoltage?\r[ 12.50]\r>"
    assert device.feed(b"foo?\r") == b"foo?\rCMD_NOT_DEFINED>"
    assert device.feed(b"echo=0\r") == b"echo=0\r>"
    assert device.feed(b"vlimit?\r") == b"[ 150]\r>"
    star = MDT693BDevice(MDT693BPersonality(echo=False, prompt="*", decimals=1))
    assert star.feed(b"XVOLTAGE=24.68\rxvoltage?\r") == b"*" + b"*[  24.7]\r*"


def test_listener_sees_every_output_change() -> None:
    seen: list[tuple[str, float]] = []
    device = MDT693BDevice(MDT693BPersonality(echo=False), on_voltage_change=lambda a, v: seen.append((a, v)))
    device.feed(b"yvoltage=3\rallvoltage=7.5\r")
    assert seen == [("y", 3.0), ("x", 7.5), ("y", 7.5), ("z", 7.5)]


def test_sim_url_options() -> None:
    with serial.serial_for_url("sim://mdt694b?echo=0&prompt=*&vlimit=100", timeout=0.05) as port:
        port.write(b"vlimit?\ryvoltage?\r")
        assert port.read(100) == b"*[ 100]\r*CMD_NOT_DEFINED*"  # fewer bytes than asked: timeout
    for bad in ("sim://mdt693b?colour=red", "sim://mdt693b?echo=2", "sim://mdt600"):
        with pytest.raises(serial.SerialException):
            serial.serial_for_url(bad)
    with attach_simulated_device("named", MDT693BDevice()):
        with pytest.raises(serial.SerialException, match="own personality"):
            serial.serial_for_url("sim://mdt693b/named?echo=0")
        with pytest.raises(ValueError, match="already attached"):
            with attach_simulated_device("named", MDT693BDevice()):
                pass
