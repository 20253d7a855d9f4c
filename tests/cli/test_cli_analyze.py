"""`wavestack analyze` on real files, and its one-line errors (exit status 2)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from wavestack.cli import main

from shared_data import DATA, require_shared_data

PSI = DATA / "psi-mirror-654nm"
pytestmark = require_shared_data()


def _run(capsys, *argv: str) -> dict:
    assert main(["analyze", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_phase_shifted_set_with_null_and_implied_conic(capsys, tmp_path) -> None:
    files = [str(PSI / f"Image{i}.jpg") for i in range(5, 11)]
    out = tmp_path / "map.npy"
    report = _run(capsys, *files, "--method", "aia", "--wavelength-nm", "654", "--modes", "15",
                  "--roc-mm", "1215", "--diameter-mm", "152.2", "--null-conic", "-0.88",
                  "--remove", "ptt", "--save-map", str(out))
    assert report["steps_estimated"] and len(report["steps_deg"]) == 6
    assert report["aperture"]["topology"] in ("simply-connected", "doubly-connected")
    assert -1.0 < report["implied_conic"] < -0.7  # measured -0.88 (see test_real_data)
    # the null of K = -0.88 removes nearly all the spherical term (0.47 waves before)
    assert abs(report["coefficients_waves"][10]) < 0.05
    assert report["rms_nm"] == pytest.approx(report["rms_waves"] * 654.0)
    saved = np.load(out)
    assert saved.shape == (600, 800) and np.isfinite(saved).sum() == report["aperture"]["valid_pixels"]


def test_zygo_file(capsys) -> None:
    report = _run(capsys, str(DATA / "zygo-dat" / "valid_zygo_dat_file.dat"), "--modes", "15")
    assert report["method"] == "file" and report["wavelength_nm"] == pytest.approx(632.8, rel=1e-6)
    assert report["rms_nm"] > 10  # a real surface map (RMS ~45 nm) in nanometres, not waves


def _one_line_error(capsys, argv: list[str], *fragments: str) -> None:
    assert main(["analyze", *argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for fragment in fragments:
        assert fragment in lines[0]


def test_unreadable_image(capsys, tmp_path) -> None:
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not a png")
    _one_line_error(capsys, [str(bad), "--wavelength-nm", "633"], "broken.png")


def test_frames_of_different_sizes(capsys, tmp_path) -> None:
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((10, 10), np.uint8))
    _one_line_error(capsys, [str(PSI / "Image5.jpg"), str(small), str(PSI / "Image7.jpg"),
                             "--wavelength-nm", "654"], "small.png")


def test_single_frame_without_carrier_fringes(capsys) -> None:
    # one frame of a phase-shifted set: closed fringes, no tilt carrier
    _one_line_error(capsys, [str(PSI / "Image5.jpg"), "--wavelength-nm", "654"], "Image5.jpg", "no carrier fringes")


def test_truncated_dat(capsys, tmp_path) -> None:
    truncated = tmp_path / "cut.dat"
    truncated.write_bytes((DATA / "zygo-dat" / "valid_zygo_dat_file.dat").read_bytes()[:5000])
    _one_line_error(capsys, [str(truncated)], "cut.dat")


def test_images_need_a_wavelength(capsys) -> None:
    _one_line_error(capsys, [str(PSI / "Image197.jpg")], "--wavelength-nm")


# ----------------------------------------------------------------------------- aperture choices

CYCLE = [str(PSI / f"Image{i}.jpg") for i in range(5, 11)]


def test_aperture_choices_are_reported_with_the_edge_circle(capsys) -> None:
    """``--aperture detected`` (default) and ``circle``: the JSON says which, and gives the edge
    circle with its uncertainties; the circle aperture's own circle is that edge circle (its
    enclosing circle runs through pixel centres, so up to ~0.5 px inside for a 285 px circle;
    the largest gap between a circle and the nearest pixel centre inside it is far smaller)."""
    detected = _run(capsys, *CYCLE, "--method", "aia", "--wavelength-nm", "654", "--modes", "15")
    circle = _run(capsys, *CYCLE, "--method", "aia", "--wavelength-nm", "654", "--modes", "15",
                  "--aperture", "circle")
    assert detected["aperture"]["choice"] == "detected" and circle["aperture"]["choice"] == "circle"
    edge = circle["aperture"]["edge_circle"]
    assert edge == detected["aperture"]["edge_circle"]  # the same detection underneath
    assert 0 < edge["radius_uncertainty"] < 1 and all(0 < s < 1 for s in edge["centre_uncertainty"])
    assert edge["points"] > 1000 and edge["rejected"] >= 0
    assert edge["radius"] - 0.5 < circle["aperture"]["radius"] <= edge["radius"]
    assert np.hypot(*np.subtract(circle["aperture"]["centre"], edge["centre"])) < 0.5


def test_a_user_mask_is_analysed(capsys, tmp_path) -> None:
    mask = np.zeros((600, 800), dtype=bool)
    mask[150:450, 250:550] = True
    path = tmp_path / "mask.npy"
    np.save(path, mask)
    report = _run(capsys, *CYCLE, "--wavelength-nm", "654", "--modes", "15", "--mask", str(path))
    assert report["aperture"]["choice"] == "mask" and "edge_circle" not in report["aperture"]
    assert report["aperture"]["valid_pixels"] == int(mask.sum())
    assert report["aperture"]["bbox"] == [250, 150, 549, 449]


def test_aperture_option_errors(capsys, tmp_path) -> None:
    small = tmp_path / "small.npy"
    np.save(small, np.ones((10, 10), dtype=bool))
    _one_line_error(capsys, [*CYCLE, "--wavelength-nm", "654", "--mask", str(small)], "small.npy", "shape")
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((600, 800), dtype=bool))
    _one_line_error(capsys, [*CYCLE, "--wavelength-nm", "654", "--mask", str(empty)], "empty.npy", "no valid pixel")
    _one_line_error(capsys, [*CYCLE, "--wavelength-nm", "654", "--mask", str(empty), "--aperture", "circle"],
                    "exclude each other")
    _one_line_error(capsys, [str(DATA / "zygo-dat" / "valid_zygo_dat_file.dat"), "--aperture", "circle"],
                    "valid_zygo_dat_file.dat", "measured map")
