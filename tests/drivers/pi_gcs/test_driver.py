"""PIHexapod against the scripted fake controller (tests/drivers/pi_gcs/conftest.py): every wire rule
the driver relies on, the checks before a move, and the same driver on a two-axis stage."""

from __future__ import annotations

import math

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers.errors import DeviceDisconnected, DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.pi_gcs import GcsError, HexapodLimits, PIHexapod

AXES = ("X", "Y", "Z", "U", "V", "W")


def hexapod_limits(step: float = 1.0) -> HexapodLimits:
    return HexapodLimits(soft={"X": (-10.0, 10.0), "Y": (-10.0, 10.0), "Z": (-5.0, 5.0),
                               "U": (-5.0, 5.0), "V": (-5.0, 5.0), "W": (-5.0, 5.0)},
                         max_step={axis: step for axis in AXES})


@pytest.fixture
def rig(fake_controller):
    with fake_controller() as fake:
        with PIHexapod(fake.url, limits=hexapod_limits(), timeout_s=0.5) as hexapod:
            yield fake, hexapod


def test_open_reads_identity_version_axes_and_travel(rig) -> None:
    fake, hexapod = rig
    assert fake.received[:4] == ["ERR?", "*IDN?", "CSV?", "SAI?"]
    assert hexapod.name == f"C-887 at {fake.url}"
    assert hexapod.controller_limits["Z"] == fake.travel["Z"]
    assert hexapod.csv() == "2.0"
    assert hexapod.axes() == AXES


def test_open_clears_a_stale_error(fake_controller) -> None:
    with fake_controller() as fake:
        fake.error = 10
        with PIHexapod(fake.url, limits=hexapod_limits(), timeout_s=0.5):
            assert fake.error == 0


def test_open_refuses_a_gcs_version_other_than_2(fake_controller) -> None:
    with fake_controller() as fake:
        fake.csv = "3.0"
        with pytest.raises(ProtocolError, match="GCS 2.0"):
            PIHexapod(fake.url, limits=hexapod_limits(), timeout_s=0.5).open()


def test_open_refuses_axes_the_controller_lacks(fake_controller) -> None:
    with fake_controller(axes=("X", "Y")) as fake:
        limits = HexapodLimits.uniform(("X", "Z"), lower=-1.0, upper=1.0, max_step=0.5)
        with pytest.raises(ProtocolError, match=r"\['Z'\]"):
            PIHexapod(fake.url, axes=("X", "Z"), limits=limits, timeout_s=0.5).open()


def test_multi_line_replies_are_parsed(rig) -> None:
    fake, hexapod = rig
    fake.pos.update({"X": 1.25, "W": -0.5})
    assert hexapod.position() == {"X": 1.25, "Y": 0.0, "Z": 0.0, "U": 0.0, "V": 0.0, "W": -0.5}


def test_a_move_and_its_err_query_go_in_one_write_and_the_controller_splits_them(rig) -> None:
    fake, hexapod = rig
    before = len(fake.packets)
    move = hexapod.move_absolute({"X": 0.5, "U": -0.25})
    assert dict(move.target) == {"X": 0.5, "U": -0.25}
    assert fake.received[-2:] == ["MOV X 0.5 U -0.25", "ERR?"]
    assert any(b"MOV X 0.5 U -0.25\nERR?\n" == p for p in fake.packets[before:])
    assert hexapod.wait_on_target(1.0)["U"] == -0.25


def test_controller_error_after_a_move_is_a_typed_gcs_error(rig) -> None:
    fake, hexapod = rig
    fake.servo["Y"] = False
    with pytest.raises(GcsError) as caught:
        hexapod.move_absolute({"Y": 0.5})
    assert caught.value.code == 5
    assert "servo off" in caught.value.meaning
    assert fake.error == 0  # ERR? read it, and so cleared it


@pytest.mark.parametrize("pose, fragment", [
    ({"X": 10.5}, "soft limits"),
    ({"Z": 1.5}, "max_step"),
    ({"X": math.nan}, "non-finite"),
    ({"Y": math.inf}, "non-finite"),
])
def test_refused_moves_send_nothing(rig, pose, fragment) -> None:
    fake, hexapod = rig
    with pytest.raises(LimitError, match=fragment):
        hexapod.move_absolute(pose)
    assert not [line for line in fake.received if line.startswith("MOV")]


def test_travel_range_read_at_connect_refuses_before_sending(fake_controller) -> None:
    travel = {"X": (-2.0, 2.0), "Y": (-2.0, 2.0)}
    with fake_controller(axes=("X", "Y"), travel=travel) as fake:
        limits = HexapodLimits.uniform(("X", "Y"), lower=-10.0, upper=10.0, max_step=5.0)
        with PIHexapod(fake.url, axes=("X", "Y"), limits=limits, timeout_s=0.5) as stage:
            with pytest.raises(LimitError, match="TMN"):
                stage.move_absolute({"X": 2.5})
    assert not [line for line in fake.received if line.startswith("MOV")]


def test_max_step_counts_from_the_position_read_back(rig) -> None:
    fake, hexapod = rig
    fake.pos["X"] = fake.target["X"] = 3.0  # moved behind the driver's back
    with pytest.raises(LimitError, match="step"):
        hexapod.move_absolute({"X": 0.0})
    hexapod.move_absolute({"X": 3.9})
    assert fake.pos["X"] == 3.9


def test_a_platform_outside_the_soft_limits_gets_no_move(rig) -> None:
    fake, hexapod = rig
    fake.pos["X"] = fake.target["X"] = 10.5
    with pytest.raises(LimitError):
        hexapod.move_absolute({"X": 10.0})


def test_unknown_axis_is_a_value_error_before_io(rig) -> None:
    fake, hexapod = rig
    count = len(fake.received)
    with pytest.raises(ValueError, match="configured axes"):
        hexapod.move_absolute({"Q": 1.0})
    assert len(fake.received) == count


def test_wait_on_target_times_out_naming_axes(rig) -> None:
    fake, hexapod = rig
    fake.hold_motion = True
    hexapod.move_absolute({"X": 0.5})
    assert hexapod.moving()["X"] is True
    with pytest.raises(DeviceTimeout, match="X"):
        hexapod.wait_on_target(0.1)


def test_stop_all_is_a_single_byte_then_err_reads_10_and_clears(rig) -> None:
    fake, hexapod = rig
    fake.hold_motion = True
    hexapod.move_absolute({"X": 0.5})
    hexapod.stop_all()
    assert fake.received[-2:] == ["#24", "ERR?"]
    stream = b"".join(fake.packets)
    assert b"\x18" in stream and b"\x18\n" not in stream  # a single byte, no LF
    assert fake.error == 0 and hexapod.moving()["X"] is False


def test_a_stop_by_the_driver_fails_the_wait_although_on_target(rig) -> None:
    fake, hexapod = rig
    fake.hold_motion = True
    hexapod.move_absolute({"Y": 0.5})
    hexapod.stop_all()
    assert hexapod.on_target()["Y"] is True  # the controller's target is now where it stopped
    with pytest.raises(GcsError) as caught:
        hexapod.wait_on_target(0.5)
    assert caught.value.code == 10


def test_a_stop_by_someone_else_fails_the_wait_through_err(rig) -> None:
    fake, hexapod = rig
    fake.hold_motion = True
    hexapod.move_absolute({"Y": 0.5})
    fake._single(24)  # the front panel, or another client, stops the platform
    with pytest.raises(GcsError) as caught:
        hexapod.wait_on_target(0.5)
    assert caught.value.code == 10 and fake.error == 0


def test_halt_reads_and_clears_error_10(rig) -> None:
    fake, hexapod = rig
    hexapod.halt()
    assert fake.received[-2:] == ["HLT X Y Z U V W", "ERR?"] and fake.error == 0


def test_ready_byte_answers(rig) -> None:
    fake, hexapod = rig
    assert hexapod.ready() is True
    fake.busy = True
    assert hexapod.ready() is False
    assert fake.received[-1] == "#7"


def test_servo_reference_pivot_velocity(rig) -> None:
    fake, hexapod = rig
    hexapod.set_servo(False)
    assert hexapod.servo() == {axis: False for axis in AXES}
    assert hexapod.referenced() == {axis: True for axis in AXES}
    hexapod.set_pivot((1.0, -2.0, 30.5))
    assert fake.received[-2] == "SPI R 1 S -2 T 30.5"
    assert hexapod.pivot() == (1.0, -2.0, 30.5)
    hexapod.set_velocity(2.5)
    assert hexapod.velocity() == 2.5


def test_pivot_is_refused_by_the_controller_while_rotated(rig) -> None:
    fake, hexapod = rig
    hexapod.move_absolute({"U": 0.5})
    with pytest.raises(GcsError) as caught:
        hexapod.set_pivot((0.0, 0.0, 10.0))
    assert caught.value.code == 9


def test_an_unanswered_query_is_explained_by_err(rig) -> None:
    fake, hexapod = rig
    fake.axes = ("X", "Y", "Z", "U", "V")  # the controller forgets W: POS? W is refused, unanswered
    with pytest.raises(GcsError) as caught:
        hexapod.position()
    assert caught.value.code == 15


def test_silence_is_a_timeout_and_the_link_recovers(rig) -> None:
    fake, hexapod = rig
    fake.mute = True
    with pytest.raises(DeviceTimeout):
        hexapod.position()
    fake.mute = False
    assert hexapod.position()["X"] == 0.0


def test_a_closed_connection_is_disconnected(fake_controller) -> None:
    with fake_controller() as fake:
        hexapod = PIHexapod(fake.url, limits=hexapod_limits(), timeout_s=0.5)
        with pytest.raises(DeviceDisconnected):
            hexapod.position()


def test_the_same_driver_drives_a_two_axis_stage_over_the_serial_url(fake_controller) -> None:
    travel = {"1": (-25.0, 25.0), "2": (-25.0, 25.0)}
    with fake_controller(axes=("1", "2"), travel=travel, idn="PI, C-884, 0, 1.0") as fake:
        limits = HexapodLimits.uniform(("1", "2"), lower=-20.0, upper=20.0, max_step=5.0)
        url = f"socket://127.0.0.1:{fake.port}"  # through serial.serial_for_url
        with PIHexapod(url, axes=("1", "2"), limits=limits, timeout_s=0.5) as stage:
            stage.move_absolute({"1": 4.0, "2": -3.0})
            assert stage.wait_on_target(1.0) == {"1": 4.0, "2": -3.0}
            assert stage.name.startswith("C-884")


def test_no_move_that_reaches_the_wire_breaks_a_limit(fake_controller) -> None:
    limits = hexapod_limits(step=0.5)
    # offsets from the start: mostly near the step limit, sometimes far, sometimes not numbers at all
    offsets = st.one_of(st.floats(min_value=-0.7, max_value=0.7), st.floats(min_value=-20.0, max_value=20.0),
                        st.sampled_from([math.nan, math.inf]))
    accepted = []
    with fake_controller() as fake, PIHexapod(fake.url, limits=limits, timeout_s=0.5) as hexapod:
        travel = hexapod.controller_limits

        @fuzz_settings(200)
        @given(st.fixed_dictionaries({}, optional={axis: offsets for axis in AXES}).filter(bool),
               st.fixed_dictionaries({axis: st.floats(min_value=-5.2, max_value=5.2) for axis in AXES}))
        def check(offset, start) -> None:
            fake.pos.update(start)
            fake.target.update(start)
            pose = {axis: start[axis] + value for axis, value in offset.items()}
            sent_before = len(fake.received)
            try:
                hexapod.move_absolute(pose)
            except LimitError:
                assert not [line for line in fake.received[sent_before:] if line.startswith("MOV")]
                return
            accepted.append(pose)
            (mov,) = [line for line in fake.received[sent_before:] if line.startswith("MOV")]
            words = mov.split()[1:]
            for axis, text in zip(words[::2], words[1::2]):
                value = float(text)
                lo, hi = limits.soft[axis]
                assert lo <= value <= hi and travel[axis][0] <= value <= travel[axis][1]
                assert abs(value - start[axis]) <= limits.max_step[axis]

        check()
    assert accepted, "no example reached the wire: the property was not exercised"
