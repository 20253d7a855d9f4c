"""A phase-shifted set, end to end through the real libraries: the MDT693B driver steps the simulated
piezo over pyserial, the USB3 Vision driver grabs triggered frames from the simulated camera over
pyusb, and the fringes in those frames move by the phase the commanded voltages produce."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from wavestack.drivers.mdt693b import MDT693B, PhaseStepCalibration, acquire_phase_steps
from wavestack.drivers.u3v import U3VCamera
from wavestack.simulators.bench import PiezoCoupling, SimulatedInterferometer
from wavestack.simulators.mdt693b import MDT693BDevice
from wavestack.simulators.optic import ApertureShape, OpticSettings, TestOptic
from wavestack.simulators import attach_simulated_device, register_serial_simulators
from wavestack.simulators.u3v import U3VSimSettings

HEIGHT, WIDTH = 96, 128
STEPS_RAD = np.array([0.0, 0.5, 1.0, 1.5]) * np.pi


def _optic() -> TestOptic:
    settings = OpticSettings(
        aperture=ApertureShape("circle", centre_px=(64.0, 48.0), radius_px=44.0),
        zernike_waves=(0.0, 0.0, 0.0, 0.6, 0.2, -0.3), carrier_cycles=(5.0, 3.0),
        noise_rms=0.0, vibration_rms_rad=0.0, bit_depth=12, seed=3,
    )
    return TestOptic(settings, HEIGHT, WIDTH)


@pytest.fixture
def bench_devices(request) -> Iterator[tuple[MDT693B, U3VCamera, SimulatedInterferometer]]:
    true_radians_per_volt = request.param
    register_serial_simulators()
    piezo_device = MDT693BDevice()
    bench = SimulatedInterferometer(
        _optic(), U3VSimSettings(width=WIDTH, height=HEIGHT, pixel_format="Mono12"), piezo_device,
        PiezoCoupling("x", true_radians_per_volt))
    with attach_simulated_device("phase-bench", piezo_device), MDT693B("sim://mdt693b/phase-bench") as piezo:
        piezo.open(timeout_s=2.0)
        camera = U3VCamera.open(backend=bench.backend, timeout_s=2.0)
        try:
            camera.set_trigger_mode(True, timeout_s=2.0)
            camera.start()
            yield piezo, camera, bench
        finally:
            camera.close()


# The config's calibration says 0.1 rad/V (10 V/rad). The bench either agrees or is 15 % stiffer.
CALIBRATION = PhaseStepCalibration(volts_per_radian=10.0, bias_v=20.0)


@pytest.mark.parametrize("bench_devices", [0.1, 0.115], indirect=True)
def test_frames_carry_the_phase_steps_the_commanded_voltages_produce(bench_devices) -> None:
    piezo, camera, bench = bench_devices
    true_rad_per_v = bench.coupling.radians_per_volt
    frames = acquire_phase_steps(piezo, camera, "x", STEPS_RAD, calibration=CALIBRATION, settle_s=0.0,
                                 timeout_s=2.0)
    assert len(frames) == len(STEPS_RAD)
    commanded = np.array([f.metadata["pzt_commanded_v"] for f in frames])
    readback = np.array([f.metadata["pzt_readback_v"] for f in frames])
    # the driver sends volts with two decimals, the controller's resolution
    np.testing.assert_allclose(commanded, [CALIBRATION.voltage_for(s) for s in STEPS_RAD], atol=0.005)
    # the controller reports to 0.01 V; the read-back tolerance is the driver's default 0.5 V
    np.testing.assert_allclose(readback, commanded, atol=0.5)

    # The simulator's ground truth per block id: the phase each frame was rendered at.
    truths = [bench.camera.truth(f.frame_id) for f in frames]
    rendered_shift = np.array([t.phase_shift_rad for t in truths])
    np.testing.assert_allclose(rendered_shift, readback * true_rad_per_v, atol=1e-9)

    # And from the pixels: fit each frame as I = a + b cos(phi_true + delta) over the aperture,
    # phi_true the simulator's wavefront plus its carrier tilt. The steps between frames must be
    # the commanded voltage steps times the bench's true coupling (not the config's calibration).
    truth = truths[0].optic
    rows, cols = np.indices((HEIGHT, WIDTH))
    fx, fy = truth.carrier_cycles
    phi = 2 * np.pi * (np.nan_to_num(truth.wavefront_waves) + fx * cols / WIDTH - fy * rows / HEIGHT)
    inside = truth.mask
    regressors = np.stack([np.ones(inside.sum()), np.cos(phi[inside]), -np.sin(phi[inside])], axis=1)
    measured = []
    for frame in frames:
        _, c, s = np.linalg.lstsq(regressors, frame.pixels[inside].astype(np.float64), rcond=None)[0]
        measured.append(np.arctan2(s, c))
    measured_steps = np.unwrap(np.asarray(measured) - measured[0])
    expected = (readback - readback[0]) * true_rad_per_v
    # 12-bit quantisation of a 0.4-of-full-scale modulation: phase errors below 1 mrad
    np.testing.assert_allclose(measured_steps, expected, atol=0.005)


@pytest.mark.parametrize("bench_devices", [0.1], indirect=True)
def test_an_out_of_limit_step_is_refused_before_anything_moves(bench_devices) -> None:
    piezo, camera, bench = bench_devices
    sent_before = bench.piezo.commands
    steep = PhaseStepCalibration(volts_per_radian=40.0, bias_v=20.0)  # 3 pi/2 -> 208 V > 150 V
    with pytest.raises(ValueError, match="150"):
        acquire_phase_steps(piezo, camera, "x", STEPS_RAD, calibration=steep, settle_s=0.0, timeout_s=2.0)
    assert not any(c.startswith("xvoltage=") for c in bench.piezo.commands[len(sent_before):])
    assert bench.piezo.voltage("x") == 0.0
