"""The platform moves at its velocity in simulated time, reports on target, keeps limits and pivot."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.simulators.pi_gcs import HexapodSimSettings, platform_transform, rotation_matrix


def _move(link, command: str) -> None:
    link.send(command.encode() + b"\n")
    assert link.error() == 0  # accepted, and read by the server before the test moves the clock


def test_a_move_runs_at_the_system_velocity_to_on_target(serve, connect, clock) -> None:
    link = connect(serve(clock=clock))
    velocity = float(link.ask("VLS?"))
    _move(link, "MOV X 3 Z -1.5")
    duration = 3.0 / velocity  # the longest travel sets the time; every axis arrives together
    clock.advance(duration / 2)
    position = {axis: float(v) for axis, v in link.values("POS? X Z").items()}
    assert position == pytest.approx({"X": 1.5, "Z": -0.75})
    assert link.values("ONT? X Z Y") == {"X": "0", "Z": "0", "Y": "1"}
    assert link.values("MOV? X Z") == {"X": "3.000000000", "Z": "-1.500000000"}
    clock.advance(duration / 2)
    assert {a: float(v) for a, v in link.values("POS? X Z").items()} == {"X": 3.0, "Z": -1.5}
    assert set(link.values("ONT?").values()) == {"1"}


def test_vls_sets_the_velocity_of_the_next_move(serve, connect, clock) -> None:
    link = connect(serve(clock=clock))
    _move(link, "VLS 0.5")
    assert float(link.ask("VLS?")) == 0.5
    _move(link, "MOV Y 1")
    clock.advance(1.0)
    assert float(link.values("POS? Y")["Y"]) == pytest.approx(0.5)


def test_a_new_target_during_a_move_replans_from_where_the_platform_is(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    _move(link, "MOV X 4")
    clock.advance(1.0)  # X = 2 at 2 mm/s
    _move(link, "MOV Y 2")
    assert simulator.controller.targets.as_dict()["X"] == 4.0
    clock.advance(1.0)  # 2 mm to go on X, 2 on Y: both done after 1 s
    assert simulator.pose["X"] == pytest.approx(4.0) and simulator.pose["Y"] == pytest.approx(2.0)


def test_halt_stops_the_named_axes_where_they_are(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    _move(link, "MOV X 4 Y 4")
    clock.advance(0.5)
    link.send(b"HLT X\n")
    assert link.error() == 10
    clock.advance(10.0)
    assert simulator.pose["X"] == pytest.approx(1.0)
    assert simulator.pose["Y"] == pytest.approx(4.0)


def test_servo_off_stops_that_axis(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    _move(link, "MOV U 4")
    clock.advance(0.5)
    _move(link, "SVO U 0")  # not a stop by command: no error 10
    clock.advance(10.0)
    assert simulator.pose["U"] == pytest.approx(1.0)


def test_the_platform_never_leaves_its_limits(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    limits = {axis: (float(link.values("TMN?")[axis]), float(link.values("TMX?")[axis]))
              for axis in simulator.pose.axes}
    settings = HexapodSimSettings()
    assert limits == dict(zip(settings.axes, zip(settings.low_limits, settings.high_limits)))
    high = limits["Z"][1]
    link.send(f"MOV Z {high + 1e-6}\n".encode())
    assert link.error() == 7
    _move(link, f"MOV Z {high}")
    clock.advance(100.0)
    assert simulator.pose["Z"] == high


def test_the_pivot_is_set_only_at_zero_rotation_and_kept(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    assert link.values("SPI?") == {"R": "0.000000000", "S": "0.000000000", "T": "0.000000000"}
    _move(link, "SPI T 50 R -2.5")
    assert simulator.controller.pivot == (-2.5, 0.0, 50.0)
    _move(link, "MOV U 0.5 X 1")
    link.send(b"SPI T 10\n")  # U is moving towards 0.5: refused
    assert link.error() == 9
    clock.advance(100.0)
    link.send(b"SPI T 10\n")
    assert link.error() == 9
    assert link.values("SPI? T") == {"T": "50.000000000"}  # kept through the moves
    _move(link, "MOV U 0")
    clock.advance(100.0)
    _move(link, "SPI T 10")  # U V W all back at 0: allowed
    assert simulator.controller.pivot == (-2.5, 0.0, 10.0)


def test_the_pivot_point_only_translates_whatever_the_rotation() -> None:
    pivot = (3.0, -4.0, 50.0)
    pose = {"X": 0.1, "Y": -0.2, "Z": 0.3, "U": 0.02, "V": -0.03, "W": 0.05}
    rotation, translation = platform_transform(pose, pivot)
    np.testing.assert_allclose(rotation @ np.array(pivot) + translation, np.array(pivot) + [0.1, -0.2, 0.3],
                               atol=1e-12)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)


def test_rotations_apply_u_then_v_then_w_about_axes_that_move_with_the_platform() -> None:
    # U = 90 about X carries the platform's +Y to +Z; V then turns about the platform's own Y axis
    # (now along the fixed Z), which leaves that point where it is: +Y ends on +Z (PI's manuals,
    # "the rotational axes ... always move together with the platform", order U -> V -> W)
    np.testing.assert_allclose(rotation_matrix(90.0, 90.0, 0.0) @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    # about fixed axes instead (Rz Ry Rx) the same pose would send +Y to +X: the rule is pinned
    fixed = rotation_matrix(0.0, 90.0, 0.0) @ rotation_matrix(90.0, 0.0, 0.0)
    np.testing.assert_allclose(fixed @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], atol=1e-12)
    # one rule for the whole bench: the simulator and the telescope model's mirror pose agree
    from wavestack.pipeline.telescope import pose_rotation

    for angles in [(0.02, -0.03, 0.05), (30.0, 45.0, -60.0), (90.0, 90.0, 0.0)]:
        np.testing.assert_allclose(rotation_matrix(*angles), pose_rotation(*angles), atol=1e-12)


def test_a_reference_move_reports_busy_then_referenced(serve, connect, clock) -> None:
    link = connect(serve(HexapodSimSettings(referenced=False, reference_time_s=2.0), clock=clock))
    assert link.values("FRF? X") == {"X": "0"}
    _move(link, "FRF")
    link.send(b"\x07")
    assert link.reply() == b"\xb0\n"
    link.send(b"\x05")
    assert int(link.reply(), 16) == 0x3F
    clock.advance(2.0)
    link.send(b"\x07")
    assert link.reply() == b"\xb1\n"
    assert set(link.values("FRF?").values()) == {"1"}
    _move(link, "MOV X 1")


def test_the_same_simulator_serves_a_two_axis_field_stage(serve, connect, clock, field_stage) -> None:
    simulator = serve(field_stage, clock=clock)
    link = connect(simulator)
    assert link.ask("SAI?") == "X \nY\n"
    assert link.ask("*IDN?") == "PI C-884 field stage (simulated)\n"
    link.send(b"SPI? \n")
    assert link.error() == 2  # no pivot on a stage
    _move(link, "MOV X 10 Y -5")
    link.send(b"\x05")
    assert int(link.reply(), 16) == 0b11
    clock.advance(2.0)  # 10 mm at 5 mm/s
    assert simulator.pose.as_dict() == {"X": 10.0, "Y": -5.0}
    link.send(b"MOV Z 1\n")
    assert link.error() == 15
