"""The random ball test: the reference's error from 32 seatings of a ball with its own 10 nm RMS figure.

Maps at the map level (the simulated optic's wavefront plus white noise, as in test_rotation), so 32
seatings cost seconds; the command's test runs the simulated station.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from wavestack.calibrate import BallTestSettings, CalibrationFailed, calibrate_reference
from wavestack.cli import main
from wavestack.pipeline import build_fitter
from wavestack.simulators.optic import ApertureShape, BallSettings, OpticSettings, ReferenceSettings, TestOptic
from wavestack.station.live_maps import MapSample

WAVELENGTH_NM = 632.8
# 20 nm RMS of reference error (Noll 5..21, as in test_rotation)
REFERENCE_NM = (0.0, 0.0, 0.0, 0.0, 10.0, -7.0, 6.0, -5.0, 7.0, 4.0, 0.0, 3.0, -3.0, 3.0, 2.0,
                4.0, -3.0, 2.0, 3.0, -2.0, 2.0)
NOISE_WAVES = 0.003


class OpticMaps:
    def __init__(self, optic: TestOptic, seed: int = 0) -> None:
        self.optic, self.rng = optic, np.random.default_rng(seed)

    def collect(self, count: int, *, max_results: int, not_before_ns: int, timeout_s: float,
                stop: object) -> list[MapSample]:
        return [MapSample(self.optic.truth(0.0).wavefront_waves + self.rng.normal(0.0, 0.05)
                          + NOISE_WAVES * self.rng.standard_normal(self.optic.shape), True, None, 1, not_before_ns)
                for _ in range(count)]


def _optic(seed: int) -> TestOptic:
    settings = OpticSettings(aperture=ApertureShape(centre_px=(48.0, 48.0), radius_px=40.0), zernike_waves=(0.0,),
                             noise_rms=0.0, reference=ReferenceSettings(zernike_nm=REFERENCE_NM),
                             ball=BallSettings(figure_nm=10.0, seed=seed))
    return TestOptic(settings, 96, 96)


def _errors(optic: TestOptic, calibration) -> tuple[float, float, float]:  # noqa: ANN001
    """(error, stated uncertainty, truth), nm RMS over the aperture, on the terms the test keeps."""
    fitter = build_fitter(calibration.mask, "circle", len(calibration.modes), pupil=calibration.pupil,
                          dtype=np.float64)
    truth = fitter.fit(np.where(calibration.mask, optic.truth(0.0).reference_waves, np.nan)).coefficients
    keep = np.diag(calibration.reference_covariance) > 0
    error = fitter.surface_rms(np.where(keep, calibration.reference - truth, 0.0)) * WAVELENGTH_NM
    basis = np.stack([fitter.surface(np.eye(len(keep))[j]) for j in range(len(keep))], axis=-1)[calibration.mask]
    stated = np.sqrt(np.mean(np.einsum("pi,ij,pj->p", basis, calibration.reference_covariance, basis))) * WAVELENGTH_NM
    return error, stated, fitter.surface_rms(np.where(keep, truth, 0.0)) * WAVELENGTH_NM


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_32_seatings_find_the_reference_within_2_5_nm_with_an_uncertainty_that_covers_it(seed: int) -> None:
    optic = _optic(seed)
    settings = BallTestSettings(seatings=32, maps_per_seating=3, settle_s=0.0, modes=21, edge_px=1)
    calibration = calibrate_reference(OpticMaps(optic, seed), lambda k: optic.reseat_ball(), settings)
    error, stated, truth = _errors(optic, calibration)
    assert truth > 15.0  # the reference's 20 nm, less power
    # the ball's 10 nm averages down as 1/sqrt(32) to ~1.8 nm over the whole sphere's figure; the cap's piston,
    # tilt and power leave with the alignment terms
    assert error < 2.5, (error, stated)
    # the stated uncertainty (the seatings' spread over sqrt(N)) is of the error's size: it covers it within 2 sigma
    assert error < 2.0 * stated and stated < 2.5, (error, stated)
    assert calibration.average.count >= 30


def test_a_station_without_a_ball_to_reseat_fails_with_the_reason() -> None:
    optic = TestOptic(OpticSettings(aperture=ApertureShape(centre_px=(48.0, 48.0), radius_px=40.0)), 96, 96)

    def seat(k: int) -> None:
        optic.reseat_ball()

    with pytest.raises(ValueError, match="no calibration ball"):
        calibrate_reference(OpticMaps(optic), seat, BallTestSettings(seatings=3, settle_s=0.0, modes=10))
    assert issubclass(CalibrationFailed, RuntimeError)


def test_the_command_runs_the_random_ball_test_on_the_simulated_station(tmp_path, capsys) -> None:  # noqa: ANN001
    """The whole path, with 8 seatings to stay cheap (the 32-seating target is the test above)."""
    from wavestack.pipeline.calibration import read_calibration

    out = tmp_path / "ball.h5"
    assert main(["calibrate", "reference", "--seatings", "8", "--maps", "3", "--settle-s", "0", "--modes", "21",
                 "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["method"] == "random-ball" and report["seatings_kept"] == 8
    truth = report["truth"]
    # 8 seatings of the 10 nm ball leave ~10 / sqrt(8) = 3.5 nm of ball over the sphere, less on these terms
    assert truth["reference_truth_nm_rms"] > 15.0 and truth["reference_error_nm_rms"] < 5.0, truth
    stored = read_calibration(out)
    assert stored.method == "random-ball" and stored.positions == 8 and stored.digest == report["calibration_file"]["sha256"]
