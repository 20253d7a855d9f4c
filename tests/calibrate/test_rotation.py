"""The rotation calibration: the part on a simulated PI rotation stage (GCS over TCP), measured at N positions.

The session tests take their maps straight from the simulated optic (its wavefront plus white noise, a
map-level station: seconds per calibration); the command's test runs the whole simulated station
(phase-shifting frames through the processor) once.
"""

from __future__ import annotations

import dataclasses
import json
import threading
from contextlib import ExitStack

import numpy as np
import pytest

from wavestack.calibrate import CalibrationFailed, RotationSettings, calibrate_rotation
from wavestack.cli import main
from wavestack.config.hexapod import build_hexapod
from wavestack.config.rotation_stage import load_rotation_stage_config
from wavestack.simulated import start_rotation_stage
from wavestack.simulators.optic import ApertureShape, OpticSettings, ReferenceSettings, TestOptic
from wavestack.station.live_maps import MapSample, UntrustedMeasurement

WAVELENGTH_NM = 632.8
PART = (0.0, 0.0, 0.0, 0.2, 0.05, -0.04, 0.03, 0.02, 0.015, -0.03, 0.02, 0.01, -0.01, 0.015, 0.01,
        0.01, -0.008, 0.006, 0.005, -0.004, 0.003)  # waves, through n = 5
# 20 nm RMS of non-symmetric reference error (Noll 5..21, none rotationally symmetric), of which the
# orders 4 (Noll 14, 15) are what N = 4 cannot separate
REFERENCE_NM = (0.0, 0.0, 0.0, 0.0, 10.0, -7.0, 6.0, -5.0, 7.0, 4.0, 0.0, 3.0, -3.0, 3.0, 2.0,
                4.0, -3.0, 2.0, 3.0, -2.0, 2.0)
NOISE_WAVES = 0.003  # per pixel and map
CIRCLE = ApertureShape(centre_px=(48.0, 48.0), radius_px=40.0)
ELLIPSE = ApertureShape(kind="ellipse", centre_px=(48.0, 48.0), semi_axes_px=(42.0, 26.0), rotation_deg=25.0)


class OpticMaps:
    """A map-level station: each map is the optic's wavefront now plus white noise; ``corrupt`` maps get a jump."""

    def __init__(self, optic: TestOptic, seed: int = 0, corrupt: frozenset[int] = frozenset()) -> None:
        self.optic, self.rng, self.corrupt, self.served = optic, np.random.default_rng(seed), corrupt, 0

    def collect(self, count: int, *, max_results: int, not_before_ns: int, timeout_s: float,
                stop: threading.Event) -> list[MapSample]:
        samples = []
        for _ in range(count):
            waves = self.optic.truth(0.0).wavefront_waves + NOISE_WAVES * self.rng.standard_normal(self.optic.shape)
            waves = waves + self.rng.normal(0.0, 0.05)  # piston drifts from map to map
            if self.served in self.corrupt:
                waves = waves + np.where(np.indices(waves.shape)[0] > 60, 1.0, 0.0)  # a fringe-order jump
            self.served += 1
            samples.append(MapSample(waves, True, None, 1, not_before_ns))
        return samples


def _optic(aperture: ApertureShape) -> TestOptic:
    reference = ReferenceSettings(zernike_nm=REFERENCE_NM, wavelength_nm=WAVELENGTH_NM)
    return TestOptic(OpticSettings(aperture=aperture, zernike_waves=PART, noise_rms=0.0, reference=reference), 96, 96)


def _stage(optic: TestOptic, stack: ExitStack):  # noqa: ANN202
    config = load_rotation_stage_config()
    simulated = start_rotation_stage(config, optic, stack)
    stage = build_hexapod(dataclasses.replace(config.stage, url=simulated.url))
    stage.open()
    stack.callback(stage.close)
    return simulated, stage


SETTINGS = RotationSettings(positions=4, maps_per_position=6, settle_s=0.0, modes=21, edge_px=1, start_deg=10.0)


@pytest.mark.parametrize("aperture", [CIRCLE, ELLIPSE], ids=["circle", "ellipse"])
def test_four_positions_give_the_parts_non_symmetric_figure_within_1_nm(aperture: ApertureShape) -> None:
    optic = _optic(aperture)
    with ExitStack() as stack:
        simulated, stage = _stage(optic, stack)
        calibration = calibrate_rotation(OpticMaps(optic), stage, SETTINGS, on_arrival=simulated.turn_part)
        errors = simulated.truth_errors(calibration, WAVELENGTH_NM)
        assert stage.position()["1"] == pytest.approx(10.0)  # returned to the start angle
    assert [r.angle_deg for r in calibration.records] == pytest.approx([10.0, 100.0, 190.0, 280.0])
    assert calibration.solution.unresolved_orders == (0, 4)
    assert errors["reference_truth_nm_rms"] > 15.0 and errors["part_truth_nm_rms"] > 20.0  # there is figure to find
    # the target: the part's non-symmetric figure (orders not 4k) within 1 nm RMS of the truth; the noise
    # of 24 maps of 0.003 waves per pixel leaves about 0.05 nm, so this bound is the method's, not the noise's
    assert errors["part_error_nm_rms"] < 1.0, errors
    assert errors["reference_error_nm_rms"] < 1.0, errors
    # the stated uncertainty is of the size of the error it claims (a few times at most either way)
    stated = float(np.sqrt(np.sum(calibration.solution.reference_stderr ** 2))) * WAVELENGTH_NM
    assert 0.2 < errors["reference_error_nm_rms"] / stated < 5.0, (errors, stated)


def test_a_corrupted_map_is_rejected_and_named_and_the_answer_keeps_its_accuracy() -> None:
    optic = _optic(CIRCLE)
    with ExitStack() as stack:
        simulated, stage = _stage(optic, stack)
        maps = OpticMaps(optic, seed=2, corrupt=frozenset({8}))  # position 2's third map
        calibration = calibrate_rotation(maps, stage, SETTINGS, on_arrival=simulated.turn_part)
        errors = simulated.truth_errors(calibration, WAVELENGTH_NM)
    assert [r.average.rejected for r in calibration.records] == [(), (2,), (), ()]
    assert errors["part_error_nm_rms"] < 1.0, errors


def test_a_stalled_stage_or_a_lost_connection_ends_the_calibration_with_the_reason() -> None:
    optic = _optic(CIRCLE)
    settings = dataclasses.replace(SETTINGS, move_timeout_s=1.0)
    with ExitStack() as stack:
        simulated, stage = _stage(optic, stack)
        arrivals = []

        def stall_after_the_first_position() -> None:
            simulated.turn_part()
            arrivals.append(1)
            simulated.simulator.faults.stick_axis("1")  # from the next move on

        with pytest.raises(CalibrationFailed, match=r"position 2 of 4 \(100 deg\): the rotation stage: .*not on target"):
            calibrate_rotation(OpticMaps(optic), stage, settings, on_arrival=stall_after_the_first_position)
        assert arrivals == [1]
    with ExitStack() as stack:
        simulated, stage = _stage(_optic(CIRCLE), stack)

        def lose_the_connection_after_two_positions() -> None:
            simulated.turn_part()
            if simulated.optic.part_rotation_deg > 50.0:
                simulated.simulator.faults.drop_connection(command="MOV")  # the next move is never made

        with pytest.raises(CalibrationFailed, match=r"position 3 of 4 \(190 deg\): the rotation stage: "):
            calibrate_rotation(OpticMaps(optic), stage, settings, on_arrival=lose_the_connection_after_two_positions)


def test_no_trusted_maps_end_the_calibration_with_the_reason() -> None:
    class Untrusted:
        def collect(self, count: int, **_: object) -> list[MapSample]:
            raise UntrustedMeasurement("expected 6 valid results in a row, got 0")

    optic = _optic(CIRCLE)
    with ExitStack() as stack:
        simulated, stage = _stage(optic, stack)
        with pytest.raises(CalibrationFailed, match=r"position 1 of 4 \(10 deg\): no trusted maps: expected 6"):
            calibrate_rotation(Untrusted(), stage, SETTINGS, on_arrival=simulated.turn_part)


def test_the_command_calibrates_the_simulated_station(capsys: pytest.CaptureFixture[str]) -> None:
    """The whole path: phase-shifting frames of the simulated station, the GCS stage, the JSON report."""
    assert main(["calibrate", "rotation", "--positions", "4", "--maps", "4", "--settle-s", "0", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["unresolved_orders"] == [0, 4] and len(report["positions_measured"]) == 4
    assert report["truth"]["part_error_nm_rms"] < 1.0, report
    assert report["truth"]["reference_error_nm_rms"] < 1.0, report
    assert report["reference_nm_rms"] > 15.0
