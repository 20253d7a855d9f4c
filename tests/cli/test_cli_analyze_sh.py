"""`wavestack analyze` on Shack-Hartmann spot images written here from a known wavefront, end to end.

Last, the real frames of a hexagonal sensor (``../shared/data/external``).

The sensor: a 400 x 420 camera of 5.5 um pixels behind a hexagonal lenslet array of pitch
28 px (154 um), turned by 5 degrees, focal length 4 mm, at 632.8 nm. Spot ``k`` is a Gaussian
(sigma 1.4 px) displaced from its lenslet centre by ``f * grad W`` at the centre, so the modal
reconstruction (gradients at the centres) has no model error and the only error is the
centroids' (pixel phase, 16-bit rounding, read noise), propagated to the coefficients in the
test itself.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import scipy.io

from wavestack.cli import main
from wavestack.pipeline.shack_hartmann import Centroider, LensletLattice, ModalReconstructor, detect_lattice
from wavestack.pipeline.zernike.circle import zernike_gradient
from wavestack.pipeline.zernike.indices import mode_list
from wavestack.pipeline.zernike.normalisation import normalisation_factor

from shared_data import DATA, require_shared_data

SIZE = (400, 420)
PITCH_PX, PIXEL_UM, FOCAL_MM, WAVELENGTH_NM = 28.0, 5.5, 4.0, 632.8
GAIN = FOCAL_MM * 1e3 * WAVELENGTH_NM * 1e-3 / PIXEL_UM**2  # px of displacement per wave/px of slope
PUPIL = (205.0, 198.0, 180.0)  # col, row, radius (px)
MODES = mode_list("noll", 15)
TRUTH = np.zeros(15)
TRUTH[[1, 2, 3, 4, 7, 10]] = [0.3, -0.2, 0.6, 0.25, -0.3, 0.1]  # waves: tilts, defocus, astigmatism, coma, spherical
TILTS = [1, 2]  # Noll 2, 3 (0-based)


def lenslets() -> LensletLattice:
    """The hexagonal lattice's lenslets whose cell lies inside the pupil."""
    a = math.radians(5.0)
    rotation = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    basis = PITCH_PX * np.array([[1.0, 0.0], [0.5, 0.5 * math.sqrt(3.0)]]) @ rotation
    n = np.arange(-10, 11)
    sites = np.stack(np.meshgrid(n, n, indexing="ij"), axis=-1).reshape(-1, 2)
    inside = np.hypot(*(sites @ basis).T) <= PUPIL[2] - PITCH_PX / math.sqrt(3.0)
    return LensletLattice("hexagonal", tuple(map(tuple, basis)), PUPIL[:2], sites[inside])


def gradient(lattice: LensletLattice) -> np.ndarray:
    """(dW/dx, dW/dy) at the lenslet centres, waves per pixel, y up, (L, 2)."""
    centres = lattice.centres()
    u, v = (centres[:, 0] - PUPIL[0]) / PUPIL[2], -(centres[:, 1] - PUPIL[1]) / PUPIL[2]
    grad_u, grad_v = zernike_gradient(MODES, u, v)
    return np.column_stack([grad_u @ TRUTH, grad_v @ TRUTH]) / PUPIL[2]


def render(positions: np.ndarray, seed: int) -> np.ndarray:
    """16-bit frame of Gaussian spots at ``positions`` ((col, row), px), offset and read noise."""
    rows, cols = np.mgrid[: SIZE[0], : SIZE[1]]
    frame = np.full(SIZE, 200.0) + np.random.default_rng(seed).normal(0.0, 4.0, SIZE)
    for col, row in positions:
        near = slice(max(int(row) - 8, 0), int(row) + 9), slice(max(int(col) - 8, 0), int(col) + 9)
        frame[near] += 30000.0 * np.exp(-((cols[near] - col) ** 2 + (rows[near] - row) ** 2) / (2 * 1.4**2))
    return np.clip(np.rint(frame), 0, 65535).astype(np.uint16)


@pytest.fixture(scope="module")
def sensor(tmp_path_factory):
    """Reference and spot images on disk, the true lattice and the spot positions."""
    folder = tmp_path_factory.mktemp("sh")
    lattice = lenslets()
    spots = lattice.centres() + GAIN * gradient(lattice) * np.array([1.0, -1.0])
    reference, image = render(lattice.centres(), 1), render(spots, 2)
    cv2.imwrite(str(folder / "reference.png"), reference)
    cv2.imwrite(str(folder / "spots.png"), image)
    return folder, lattice, spots, reference, image


def tolerance(sensor) -> np.ndarray:
    """Per-coefficient bound: 5 sigma of the measured centroid noise through the reconstructor."""
    _, lattice, spots, reference, image = sensor
    centroider = Centroider.build(lattice, SIZE)
    errors = np.concatenate([centroider.measure(reference).centroids - lattice.centres(),
                             centroider.measure(image).centroids - spots])
    sigma_px = float(np.sqrt(np.mean(errors**2)))  # per axis, per image
    # slope of one spot difference (two images): sqrt(2) sigma, in waves per pixel
    sigma_slope = math.sqrt(2.0) * sigma_px / GAIN
    reconstructor = ModalReconstructor.for_circle(lattice.centres_xy(), (PUPIL[0], -PUPIL[1]), PUPIL[2], MODES)
    return 5.0 * sigma_slope * np.sqrt(np.sum(reconstructor.matrix**2, axis=1)) + 1e-9


def analyze(capsys, *argv: str) -> dict:
    assert main(["analyze", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


COMMON = ["--focal-length-mm", str(FOCAL_MM), "--pixel-um", str(PIXEL_UM), "--wavelength-nm", str(WAVELENGTH_NM),
          "--modes", "15", "--pupil-px", ",".join(map(str, PUPIL))]


def test_against_a_reference_image(capsys, sensor) -> None:
    folder, lattice, *_ = sensor
    report = analyze(capsys, str(folder / "spots.png"), "--reference", str(folder / "reference.png"), *COMMON)
    assert report["lattice"]["kind"] == "hexagonal" and report["used_lenslets"] == lattice.count
    assert report["lattice"]["pitch_px"] == pytest.approx(PITCH_PX, abs=0.01)
    found = np.array(report["coefficients_waves"])
    bound = tolerance(sensor)
    assert np.all(np.abs(found - TRUTH) <= bound), (found - TRUTH, bound)
    assert bound.max() < 0.01  # a meaningful check: lambda / 100
    assert np.allclose(report["coefficients_nm"], found * WAVELENGTH_NM)
    assert report["rms_waves"] == pytest.approx(np.sqrt(np.sum(found[1:] ** 2)))


def test_from_the_lenslet_description(capsys, sensor) -> None:
    folder, *_ = sensor
    report = analyze(capsys, str(folder / "spots.png"), "--lenslet-pitch-um", str(PITCH_PX * PIXEL_UM), *COMMON)
    found = report["coefficients_waves"]
    assert [found[j] for j in TILTS] == [None, None] and not report["tilt_measured"]
    others = [j for j in range(15) if j not in TILTS]
    error = np.array([found[j] for j in others]) - TRUTH[others]
    # one image instead of two and the ideal centres: at most the reference run's noise; the
    # lattice rotation comes from the spots, whose error is a fraction of that noise
    assert np.all(np.abs(error) <= tolerance(sensor)[others])


def test_text_output_and_ansi_ordering(capsys, sensor) -> None:
    folder, *_ = sensor
    assert main(["analyze", str(folder / "spots.png"), "--reference", str(folder / "reference.png"), *COMMON[:6],
                 "--modes", "6", "--ordering", "ansi"]) == 0
    text = capsys.readouterr().out
    assert "hexagonal lattice" in text and "defocus" in text.lower()
    assert text.count("\n") >= 6


def test_fringe_ordering_and_removed_terms(capsys, sensor) -> None:
    folder, *_ = sensor
    report = analyze(capsys, str(folder / "spots.png"), "--reference", str(folder / "reference.png"), *COMMON,
                     "--ordering", "fringe", "--remove", "pttp")
    assert report["normalisation"] == "edge"
    truth = dict(zip(MODES, TRUTH))
    for (n, m), value in zip(map(tuple, report["mode_indices"]), report["coefficients_waves"]):
        if (n, m) in ((0, 0), (1, 1), (1, -1), (2, 0)):
            assert value == 0.0
        elif (n, m) in truth:
            # unit RMS -> unit edge value multiplies by N_rms; 0.01 waves bounds the unit-RMS
            # error (test_against_a_reference_image derives it), scaled the same way
            scale = normalisation_factor(n, m, "rms")
            assert abs(value - truth[(n, m)] * scale) < 0.01 * scale


def one_line_error(capsys, argv: list[str], *fragments: str) -> None:
    assert main(["analyze", *argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_an_image_without_spots(capsys, tmp_path, sensor) -> None:
    folder, *_ = sensor
    flat = tmp_path / "flat.png"  # the camera's offset and read noise, no light
    cv2.imwrite(str(flat), render(np.empty((0, 2)), seed=3))
    one_line_error(capsys, [str(flat), "--reference", str(folder / "reference.png"), *COMMON], "flat.png", "no spots")
    one_line_error(capsys, [str(folder / "spots.png"), "--reference", str(flat), *COMMON], "flat.png", "no spots")


def test_images_of_different_sizes(capsys, tmp_path, sensor) -> None:
    folder, *_ = sensor
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((100, 100), np.uint16))
    one_line_error(capsys, [str(folder / "spots.png"), "--reference", str(small), *COMMON], "small.png", "shape")


@pytest.mark.parametrize("left_out", ["--focal-length-mm", "--pixel-um", "--wavelength-nm"])
def test_a_missing_option(capsys, sensor, left_out) -> None:
    folder, *_ = sensor
    argv = list(COMMON)
    del argv[argv.index(left_out): argv.index(left_out) + 2]
    one_line_error(capsys, [str(folder / "spots.png"), "--reference", str(folder / "reference.png"), *argv],
                   "spots.png", left_out)


def test_neither_reference_nor_pitch(capsys, sensor) -> None:
    folder, *_ = sensor
    one_line_error(capsys, [str(folder / "spots.png"), *COMMON], "spots.png", "--reference", "--lenslet-pitch-um")


def test_a_pitch_that_does_not_match_the_spots(capsys, sensor) -> None:
    folder, *_ = sensor
    one_line_error(capsys, [str(folder / "spots.png"), "--lenslet-pitch-um", str(2 * PITCH_PX * PIXEL_UM), *COMMON],
                   "spots.png", "px apart")


@pytest.mark.parametrize("option", [["--aperture", "circle"], ["--mask", "mask.png"]])
def test_interferogram_aperture_options_are_refused(capsys, sensor, option) -> None:
    folder, *_ = sensor
    one_line_error(capsys, [str(folder / "spots.png"), "--reference", str(folder / "reference.png"), *COMMON, *option],
                   "spots.png", "--aperture and --mask apply to interferograms")


@require_shared_data()
def test_a_real_hexagonal_sensor(capsys, tmp_path) -> None:
    """The real frames of a hexagonal 127-lenslet sensor (mshwfs: 300 um pitch on 7.4 um pixels,
    40.5 px; a reference and an aberrated frame, MATLAB files written here as float TIFFs): the
    lattice is found hexagonal with every lenslet, at the datasheet's pitch."""
    frames = {}
    for name, key in (("mshwfs_sh_flat.mat", "sh_flat"), ("mshwfs_img.mat", "img")):
        frames[key] = tmp_path / f"{key}.tif"
        assert cv2.imwrite(str(frames[key]), scipy.io.loadmat(DATA / "external" / name)[key].astype(np.float32))
    report = analyze(capsys, str(frames["img"]), "--reference", str(frames["sh_flat"]), "--focal-length-mm", "5",
                     "--pixel-um", "7.4", "--wavelength-nm", "632.8", "--modes", "15")
    lattice = report["lattice"]
    assert lattice["kind"] == "hexagonal" and lattice["lenslets"] == report["used_lenslets"] == 127
    assert lattice["pitch_px"] == pytest.approx(300 / 7.4, rel=0.01)
    assert report["condition"] < 2.0  # 127 lenslets over the disk they cover: 15 modes well apart
    found = detect_lattice(cv2.imread(str(frames["img"]), cv2.IMREAD_UNCHANGED))
    assert found.kind == "hexagonal" and found.count == 127  # the aberrated frame alone too


def test_the_config_describes_the_sensor_alone(capsys, sensor) -> None:
    folder, *_ = sensor
    station = Path(__file__).resolve().parents[1] / "configs" / "sh-small.toml"
    one_line_error(capsys, [str(folder / "spots.png"), "--config", str(station), "--reference",
                            str(folder / "reference.png")], "spots.png", "--config describes the sensor", "--reference")
    # an interferometer station's file measures the image as that station's frames: its sets are five
    interferometer = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
    one_line_error(capsys, [str(folder / "spots.png"), "--config", str(interferometer)], "spots.png",
                   "expected 5 frame(s) per set, got 1")
