"""The simulated controller's MDT693A compatibility mode, seen by a plain pyserial client (not our driver).

What each exchange must look like comes from the controller's documentation as recorded in
``wavestack.drivers.mdt693b.command_sets`` (``cm?``/``cm=`` from the MDT693B firmware 1.10 help text and
a firmware 1.05 log; the single-letter MDT693A commands, prompt ``*`` and error ``!``). The bytes are
written out here by hand, so a misreading in the simulator cannot hide behind the driver's parser.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import ExitStack

import pytest
import serial

from wavestack.simulators import attach_simulated_device, register_serial_simulators
from wavestack.simulators.mdt693b import MDT693BDevice, MDT693BPersonality, PtyBridge


@pytest.fixture(autouse=True)
def _sim_urls() -> None:
    register_serial_simulators()


@pytest.fixture(params=["sim", "pty"])
def port_to(request: pytest.FixtureRequest) -> Iterator:
    """Open a raw pyserial port onto a device over the transport under test."""
    with ExitStack() as stack:
        def open_port(device: MDT693BDevice, name: str = "raw") -> serial.SerialBase:
            if request.param == "sim":
                stack.enter_context(attach_simulated_device(name, device))
                url = f"sim://{device.personality.model.lower()}/{name}"
            else:
                url = stack.enter_context(PtyBridge(device)).port_path
            return stack.enter_context(serial.serial_for_url(url, baudrate=115200, timeout=1.0))

        yield open_port


def ask(port: serial.SerialBase, command: bytes, expected_length: int) -> bytes:
    """Write ``command`` + CR; return what arrives (``expected_length`` bytes, then nothing more)."""
    port.reset_input_buffer()
    port.write(command + b"\r")
    answer = port.read(expected_length)
    time.sleep(0.05)
    return answer + port.read(port.in_waiting)


def quiet(**options: object) -> MDT693BPersonality:
    return MDT693BPersonality(echo=False, **options)  # type: ignore[arg-type]


def test_cm_query_and_switch_to_the_mdt693a_command_set(port_to) -> None:
    device = MDT693BDevice(quiet())
    port = port_to(device)
    assert ask(port, b"cm?", 34) == b"[MDT693A Compatibility Mode Off]\r>"
    assert ask(port, b"cm=1", 1) == b"*"  # the answer already ends with the new mode's prompt
    assert device.compatibility_mode is True
    assert ask(port, b"cm?", 34) == b"*[MDT693A Compatibility Mode On]\r*"
    # the MDT693A set: set X, read it back (one decimal), read the limits and the limit switch
    assert ask(port, b"XV12.34", 1) == b"*"
    assert device.voltage("x") == pytest.approx(12.34)
    assert ask(port, b"XR?", 10) == b"*[  12.3]\r*"
    assert ask(port, b"YV7", 1) == b"*" and ask(port, b"yr?", 10) == b"*[   7.0]\r*"  # case-insensitive
    assert ask(port, b"XL?", 10) == b"*[   0.0]\r*"
    assert ask(port, b"XH?", 10) == b"*[ 150.0]\r*"
    assert ask(port, b"%", 8) == b"*[ 150]\r*"
    assert ask(port, b"AV20", 1) == b"*"
    assert [device.voltage(axis) for axis in "xyz"] == [20.0, 20.0, 20.0]
    # commands of the other set, unknown commands and bad arguments answer '!' instead of the prompt
    for refused in (b"xvoltage?", b"xvoltage=5", b"vlimit?", b"echo=0", b"QQ", b"XV", b"XVabc", b"XV151"):
        assert ask(port, refused, 1) == b"!", refused
    assert device.voltage("x") == 20.0
    assert ask(port, b"cm=0", 1) == b">"
    assert device.compatibility_mode is False
    assert ask(port, b"XR?", 16) == b"CMD_NOT_DEFINED>"
    assert ask(port, b"xvoltage?", 10) == b"[ 20.00]\r>"


def test_limits_and_the_limit_switch_clip_in_the_mdt693a_set(port_to) -> None:
    device = MDT693BDevice(quiet(compatibility_mode=True, vlimit_v=100.0))
    port = port_to(device)
    assert ask(port, b"%", 8) == b"*[ 100]\r*"
    assert ask(port, b"XH80", 1) == b"*" and ask(port, b"XL5", 1) == b"*"
    assert ask(port, b"XH?", 10) == b"*[  80.0]\r*" and ask(port, b"XL?", 10) == b"*[   5.0]\r*"
    assert ask(port, b"XV120", 1) == b"*"  # clipped silently, as the B set does: only a read-back shows it
    assert ask(port, b"XR?", 10) == b"*[  80.0]\r*"
    assert ask(port, b"XV1", 1) == b"*" and device.voltage("x") == 5.0


def test_echo_in_the_mdt693a_set_is_the_command_in_lower_case(port_to) -> None:
    device = MDT693BDevice(MDT693BPersonality(echo=True, compatibility_mode=True))
    port = port_to(device)
    assert ask(port, b"XV1.5", 7) == b"xv1.5\r*"
    assert ask(port, b"XR?", 14) == b"xr?\r*[   1.5]\r*"
    assert ask(port, b"BOGUS", 7) == b"bogus\r!"
    assert ask(port, b"E", 3) == b"e\r*"  # E toggles the echo
    assert device.echo is False
    assert ask(port, b"XR?", 10) == b"*[   1.5]\r*"


def test_identity_in_the_mdt693a_set(port_to) -> None:
    device = MDT693BDevice(quiet(compatibility_mode=True))
    port = port_to(device)
    port.reset_input_buffer()
    port.write(b"I\r")
    answer = port.read_until(b"www.thorlabs.com\r*")
    assert answer.startswith(b"*Model MDT693B Piezo Control Module\rFirmware Version: 1.10\r")
    assert answer.endswith(b"\r*")


def test_a_real_mdt693a_has_no_compatibility_switch(port_to) -> None:
    device = MDT693BDevice(quiet(model="MDT693A", firmware="3.01"))
    port = port_to(device, "mdt693a")
    assert device.compatibility_mode is True
    assert ask(port, b"cm?", 1) == b"!" and ask(port, b"cm=0", 1) == b"!"
    assert ask(port, b"XV3", 1) == b"*" and ask(port, b"ZR?", 10) == b"*[   0.0]\r*"
    port.write(b"I\r")
    assert port.read_until(b"www.thorlabs.com\r*").startswith(b"*Model MDT693A Piezo Control Module\r")


def test_single_axis_model_in_the_mdt694a_set(port_to) -> None:
    device = MDT693BDevice(quiet(model="MDT694B"))
    port = port_to(device, "single")
    assert ask(port, b"cm?", 34) == b"[MDT694A Compatibility Mode Off]\r>"
    assert ask(port, b"cm=1", 1) == b"*"
    assert ask(port, b"YR?", 1) == b"!" and ask(port, b"AV3", 1) == b"!"
    assert ask(port, b"XV3", 1) == b"*" and ask(port, b"XR?", 10) == b"*[   3.0]\r*"


def test_sim_url_chooses_the_compatibility_mode() -> None:
    with serial.serial_for_url("sim://mdt693b?echo=0&cm=1", timeout=1.0) as port:
        assert ask(port, b"%", 8) == b"*[ 150]\r*"
    with serial.serial_for_url("sim://mdt693a?echo=0", timeout=1.0) as port:
        assert ask(port, b"cm?", 1) == b"!"
    with pytest.raises(serial.SerialException):
        serial.serial_for_url("sim://mdt693b?cm=2")
