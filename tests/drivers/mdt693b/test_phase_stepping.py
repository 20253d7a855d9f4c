"""Phase stepping: piezo steps and camera frames in lock-step, limits checked before anything moves."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest

from wavestack.drivers import Frame, LimitError
from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration, TriggeredFrameSource, acquire_phase_steps
from wavestack.simulators.mdt693b import MDT693BDevice, MDT693BPersonality
from wavestack.simulators import attach_simulated_device, register_serial_simulators

CALIBRATION = PhaseStepCalibration(volts_per_radian=2.0, bias_v=50.0)
FOUR_STEPS = (0.0, math.pi / 2, math.pi, 3 * math.pi / 2)


class FringeCamera:
    """In-test camera: renders I = A + B cos(phi(x, y) + delta), delta from the simulated piezo voltage.

    It listens to the device's output (``on_voltage_change``) as an interferometer would see the
    mirror move, and records the voltage at each trigger.
    """

    def __init__(self, device: MDT693BDevice, calibration: PhaseStepCalibration, shape: tuple[int, int]) -> None:
        yy, xx = np.mgrid[0: shape[0], 0: shape[1]]
        self.phase = 0.3 * xx - 0.2 * yy + 0.01 * (xx - shape[1] / 2) ** 2  # a test wavefront, rad
        self.calibration = calibration
        self.volts = device.voltage("x")
        self.triggered_at: list[float] = []
        self.frames_read = 0
        device.on_voltage_change = self._moved

    def _moved(self, axis: str, volts: float) -> None:
        if axis == "x":
            self.volts = volts

    def trigger_software(self, timeout_s: float) -> None:
        self.triggered_at.append(self.volts)

    def read_frame(self, timeout_s: float) -> Frame:
        delta = (self.triggered_at[-1] - self.calibration.bias_v) / self.calibration.volts_per_radian
        pixels = 2000.0 + 1000.0 * np.cos(self.phase + delta)
        self.frames_read += 1
        return Frame(self.frames_read, time.time_ns(), 0, pixels.astype(np.uint16), {"exposure_us": 100})


@pytest.fixture
def bench() -> Iterator[tuple[MDT693B, MDT693BDevice]]:
    register_serial_simulators()
    device = MDT693BDevice(MDT693BPersonality(echo=False, vlimit_v=100.0))
    with attach_simulated_device("phase-bench", device):
        piezo = MDT693B("sim://mdt693b/phase-bench", software_max_v=90.0)
        with piezo:
            yield piezo, device


def test_camera_satisfies_the_protocol(bench: tuple[MDT693B, MDT693BDevice]) -> None:
    assert isinstance(FringeCamera(bench[1], CALIBRATION, (4, 4)), TriggeredFrameSource)


def test_four_step_sequence_recovers_the_wavefront(bench: tuple[MDT693B, MDT693BDevice]) -> None:
    piezo, device = bench
    camera = FringeCamera(device, CALIBRATION, (24, 32))
    frames = acquire_phase_steps(piezo, camera, "x", FOUR_STEPS, calibration=CALIBRATION, settle_s=0.0,
                                 timeout_s=1.0)
    assert len(frames) == 4 and [f.frame_id for f in frames] == [1, 2, 3, 4]
    expected_v = [CALIBRATION.voltage_for(step) for step in FOUR_STEPS]
    # the piezo was at the step's voltage when the camera was triggered (two decimals on the wire)
    assert camera.triggered_at == pytest.approx(expected_v, abs=0.005)
    for frame, step, volts in zip(frames, FOUR_STEPS, expected_v):
        assert frame.metadata["pzt_axis"] == "x"
        assert frame.metadata["phase_step_rad"] == step
        assert frame.metadata["pzt_commanded_v"] == pytest.approx(volts, abs=0.005)
        assert frame.metadata["pzt_readback_v"] == pytest.approx(volts, abs=0.005)
        assert frame.metadata["exposure_us"] == 100  # the camera's own metadata is kept
    # four-bucket algorithm: phi = atan2(I4 - I2, I1 - I3) (Creath 1988)
    i1, i2, i3, i4 = (f.pixels.astype(float) for f in frames)
    recovered = np.arctan2(i4 - i2, i1 - i3)
    residual = np.angle(np.exp(1j * (recovered - camera.phase)))
    # 0.005 V wire rounding / 2 V per rad = 2.5 mrad step error, and uint16 rounding of a 1000-count
    # modulation adds ~1 mrad; 0.01 rad bounds both with margin
    assert np.max(np.abs(residual)) < 0.01
    assert [c for c in device.commands if c.startswith("xvoltage")] == [
        cmd for volts in expected_v for cmd in (f"xvoltage={volts:.2f}", "xvoltage?")]


def test_a_step_beyond_the_limits_stops_everything_before_it_starts(bench: tuple[MDT693B, MDT693BDevice]) -> None:
    piezo, device = bench
    camera = FringeCamera(device, CALIBRATION, (4, 4))
    steps = (0.0, 10.0, 25.0)  # 25 rad -> 100 V, above the 90 V software limit
    before = device.received
    with pytest.raises(LimitError, match="25 rad -> 100 V"):
        acquire_phase_steps(piezo, camera, "x", steps, calibration=CALIBRATION, settle_s=0.0, timeout_s=1.0)
    assert device.received == before
    assert camera.triggered_at == []


@pytest.mark.parametrize(("steps", "settle_s", "timeout_s"), [((), 0.0, 1.0), ((0.0, math.nan), 0.0, 1.0),
                                                                ((0.0,), -1.0, 1.0), ((0.0,), 0.0, 0.0)])
def test_bad_arguments(bench: tuple[MDT693B, MDT693BDevice], steps: tuple[float, ...], settle_s: float,
                       timeout_s: float) -> None:
    piezo, device = bench
    with pytest.raises(ValueError):
        acquire_phase_steps(piezo, FringeCamera(device, CALIBRATION, (4, 4)), "x", steps,
                            calibration=CALIBRATION, settle_s=settle_s, timeout_s=timeout_s)


def test_calibration_is_linear_and_validated() -> None:
    assert CALIBRATION.voltage_for(0.0) == 50.0
    assert CALIBRATION.voltage_for(-math.pi) == pytest.approx(50.0 - 2.0 * math.pi)
    for bad in ((0.0, 1.0), (math.inf, 1.0), (1.0, math.nan)):
        with pytest.raises(ValueError):
            PhaseStepCalibration(*bad)
