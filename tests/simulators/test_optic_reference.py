"""The simulated interferometer's reference error and the part's rotary mount: what every frame sees, and the truth
kept apart (part, reference) so that a calibration can be judged."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.config import DEFAULT_CONFIG
from wavestack.config.schema import ConfigError
from wavestack.config.station import parse_station_config
from wavestack.pipeline import build_fitter
from wavestack.simulated import as_simulator
from wavestack.simulators.optic import ApertureShape, OpticSettings, ReferenceSettings, TestOptic
from wavestack.simulators.surface_settings import SurfaceSettings

SIZE = 64
DISK = ApertureShape(centre_px=(32.0, 32.0), radius_px=28.0)
PART = (0.0, 0.0, 0.0, 0.1, 0.05, -0.03, 0.02, 0.01, 0.015, -0.02, 0.01)  # waves
REFERENCE_NM = (0.0, 0.0, 0.0, 0.0, 12.0, -8.0, 3.0, 0.0, 0.0, 5.0)  # nm of wavefront
WAVELENGTH_NM = 632.8


def _optic(**changes: object) -> TestOptic:
    settings = OpticSettings(aperture=DISK, zernike_waves=PART, noise_rms=0.0,
                             reference=ReferenceSettings(zernike_nm=REFERENCE_NM, wavelength_nm=WAVELENGTH_NM))
    return TestOptic(settings.__class__(**{**settings.__dict__, **changes}), SIZE, SIZE)


def test_every_frame_sees_the_part_plus_the_reference_and_the_truth_keeps_them_apart() -> None:
    optic = _optic()
    truth = optic.truth(0.0)
    fitter = build_fitter(truth.mask, "circle", 11, pupil=truth.pupil_px, dtype=np.float64)
    seen = fitter.fit(truth.wavefront_waves).coefficients
    reference = fitter.fit(truth.reference_waves).coefficients
    expected_reference = np.zeros(11)
    expected_reference[: len(REFERENCE_NM)] = np.array(REFERENCE_NM) / WAVELENGTH_NM
    assert np.allclose(reference, expected_reference, atol=1e-9)
    assert np.allclose(seen, np.array(PART) + expected_reference, atol=1e-9)
    assert np.array_equal(truth.coefficients_waves, PART)
    # the frames render that sum: a four-step set's phase is 2 pi (part + reference) inside the aperture
    frames = [optic.interferogram(0.0, k * np.pi / 2)[0].astype(float) for k in range(4)]
    phase = np.arctan2(frames[3] - frames[1], frames[0] - frames[2])
    expected = 2 * np.pi * truth.wavefront_waves
    error = np.angle(np.exp(1j * (phase - expected)))[truth.mask]
    assert np.sqrt(np.mean((error - error.mean()) ** 2)) < 0.01  # rad: 12-bit rounding only


def test_the_part_turns_on_its_mount_and_the_reference_does_not() -> None:
    optic = _optic()
    before = optic.truth(0.0)
    optic.rotate_part(90.0)
    after = optic.truth(0.0)
    assert after.rotation_deg == 90.0 and after.aperture_revision == before.aperture_revision + 1
    assert np.array_equal(after.reference_waves, before.reference_waves, equal_nan=True)
    part_before = before.wavefront_waves - before.reference_waves
    part_after = after.wavefront_waves - after.reference_waves
    # a quarter turn counter-clockwise as displayed about the disk's centre (the grid's centre pixel 32, 32)
    turned = np.rot90(part_before[4:61, 4:61])
    assert np.allclose(part_after[4:61, 4:61], turned, atol=1e-12, equal_nan=True)
    assert not np.allclose(part_after[4:61, 4:61], part_before[4:61, 4:61], equal_nan=True)


def test_a_surface_map_is_not_turned_and_bad_settings_are_named() -> None:
    optic = _optic(surface=SurfaceSettings(zernike_nm=(0.0, 0.0, 0.0, 10.0)))
    with pytest.raises(ValueError, match="surface map"):
        optic.rotate_part(45.0)
    with pytest.raises(ValueError, match="zernike_nm\\[1\\]"):
        ReferenceSettings(zernike_nm=(0.0, float("nan")))
    with pytest.raises(ValueError, match="map_rms_nm: given without map_file"):
        ReferenceSettings(map_rms_nm=5.0)


def test_the_station_file_sets_the_reference_with_the_stations_wavelength() -> None:
    text = DEFAULT_CONFIG.read_text(encoding="utf-8") + "\n[optic.reference]\nzernike_nm = [0.0, 0.0, 0.0, 0.0, 20.0]\n"
    config = parse_station_config(text, source="bench.toml")
    reference = as_simulator(config.optic, OpticSettings, source="bench.toml", table="optic").reference
    assert reference == ReferenceSettings(zernike_nm=(0.0, 0.0, 0.0, 0.0, 20.0), wavelength_nm=632.8)
    with pytest.raises(ConfigError, match=r"\[optic.reference\] wavelength_nm = 500 does not match"):
        parse_station_config(text + "wavelength_nm = 500.0\n", source="bench.toml")
    with pytest.raises(ConfigError, match=r"\[optic.reference\] map_file = 'nowhere.npy': no such file"):
        parse_station_config(text + "map_file = 'nowhere.npy'\n", source="bench.toml")
