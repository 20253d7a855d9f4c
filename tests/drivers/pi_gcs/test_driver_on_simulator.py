"""Our GCS driver against our GCS simulator: two independent readings of PI's rules meet on the wire.

The driver and the simulator were written separately (neither imports the other's parser); every
exchange here goes over a real socket or a real pseudo-terminal, as with a C-887 controller.
"""

from __future__ import annotations

import time

import pytest

from wavestack.drivers import DeviceTimeout, LimitError
from wavestack.drivers.pi_gcs import GcsError, HexapodLimits, PIHexapod
from wavestack.simulators.pi_gcs import GcsController, GcsPtyBridge, HexapodSimSettings, HexapodSimulator

AXES = ("X", "Y", "Z", "U", "V", "W")
LIMITS = HexapodLimits.uniform(AXES, lower=-5.0, upper=5.0, max_step=0.5)
WAIT_S = 30.0  # a bound on waiting, never a timing assertion


def _hexapod(simulator: HexapodSimulator, limits: HexapodLimits = LIMITS) -> PIHexapod:
    return PIHexapod(f"tcp://127.0.0.1:{simulator.port}", AXES, limits=limits, timeout_s=5.0)


def test_the_driver_opens_moves_and_reads_back_through_the_simulator() -> None:
    with HexapodSimulator(HexapodSimSettings(velocity=20.0)) as simulator, _hexapod(simulator) as hexapod:
        assert hexapod.csv().startswith("2.")
        assert "C-887" in hexapod.identify() and hexapod.axes() == AXES
        assert hexapod.controller_limits["Z"] == (-6.5, 6.5)
        assert all(hexapod.servo().values()) and all(hexapod.referenced().values())
        target = {"X": 0.25, "Y": -0.1, "Z": 0.05, "U": 0.02, "V": -0.03, "W": 0.0}
        move = hexapod.move_absolute(target)
        assert move.target["X"] == pytest.approx(0.25)
        reached = hexapod.wait_on_target(WAIT_S)
        for axis, value in target.items():
            assert reached[axis] == pytest.approx(value, abs=1e-9)
            assert simulator.pose[axis] == pytest.approx(value, abs=1e-9)  # what the platform really did
        assert hexapod.ready() and not any(hexapod.moving().values())


def test_a_move_beyond_the_soft_limits_or_the_step_never_reaches_the_wire() -> None:
    with HexapodSimulator(HexapodSimSettings(velocity=20.0)) as simulator, _hexapod(simulator) as hexapod:
        before = simulator.pose.as_dict()
        for pose in ({"X": 5.5}, {"X": 0.6}, {"U": float("nan")}):  # soft limit, step 0.5, non-finite
            with pytest.raises((LimitError, ValueError)):
                hexapod.move_absolute(pose)
        assert simulator.pose.as_dict() == before
        assert not any(line.upper().startswith("MOV ") for line in simulator.controller.commands)  # decoded at the far end


def test_a_controller_error_becomes_a_typed_error_with_its_code() -> None:
    with HexapodSimulator(HexapodSimSettings(velocity=20.0)) as simulator, _hexapod(simulator) as hexapod:
        simulator.faults.fail_next(7, command="MOV")  # PI: 7 = position out of limits
        with pytest.raises(GcsError) as raised:
            hexapod.move_absolute({"X": 0.1})
        assert raised.value.code == 7
        assert hexapod.error_code() == 0  # ERR? read and cleared it


def test_stop_all_halts_a_slow_move_and_the_wait_reports_the_stop() -> None:
    with HexapodSimulator(HexapodSimSettings(velocity=0.01)) as simulator, _hexapod(simulator) as hexapod:
        hexapod.move_absolute({"X": 0.4})  # 40 s at 0.01 mm/s
        deadline = time.monotonic() + WAIT_S
        while not hexapod.moving()["X"] and time.monotonic() < deadline:
            time.sleep(0.01)
        hexapod.stop_all()  # #24, then ERR? must read 10 (and clears it)
        stopped_at = simulator.pose["X"]
        assert 0.0 <= stopped_at < 0.4
        with pytest.raises(GcsError):
            hexapod.wait_on_target(WAIT_S)  # a stopped move is not an arrival
        assert simulator.pose["X"] == pytest.approx(stopped_at, abs=1e-6)


def test_a_stuck_axis_ends_the_wait_in_a_timeout_not_an_arrival() -> None:
    with HexapodSimulator(HexapodSimSettings(velocity=20.0)) as simulator, _hexapod(simulator) as hexapod:
        simulator.faults.stick_axis("Y")
        hexapod.move_absolute({"Y": 0.2})
        with pytest.raises(DeviceTimeout, match="not on target") as raised:
            hexapod.wait_on_target(1.0)
        assert "Y" in str(raised.value)
        hexapod.halt()
        assert simulator.pose["Y"] == pytest.approx(0.0, abs=1e-12)  # the stuck axis never moved


def test_the_field_stage_is_the_same_driver_on_two_axes_over_rs232() -> None:
    settings = HexapodSimSettings(axes=("1", "2"), low_limits=(-50.0, -50.0), high_limits=(50.0, 50.0),
                                  velocity=50.0, max_velocity=50.0, pivot=None)
    with GcsPtyBridge(GcsController(settings)) as bridge:
        limits = HexapodLimits.uniform(("1", "2"), lower=-25.0, upper=25.0, max_step=50.0)
        with PIHexapod(bridge.port_path, ("1", "2"), limits=limits, timeout_s=5.0) as stage:
            assert stage.axes() == ("1", "2")
            stage.move_absolute({"1": 12.5, "2": -7.0})
            reached = stage.wait_on_target(WAIT_S)
            assert reached == pytest.approx({"1": 12.5, "2": -7.0}, abs=1e-9)
            assert bridge.controller.pose.as_dict() == pytest.approx({"1": 12.5, "2": -7.0}, abs=1e-9)
