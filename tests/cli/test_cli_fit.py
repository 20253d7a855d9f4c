"""`wavestack fit` end to end: output, files, and one-line errors with exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from wavestack.cli import main
from wavestack.cli.example import synthetic_example
from wavestack.pipeline import build_fitter


@pytest.fixture()
def example_files(tmp_path):
    example = synthetic_example()
    wavefront = tmp_path / "wavefront.npy"
    np.save(wavefront, example.wavefront)
    mask_png = tmp_path / "mask.png"
    cv2.imwrite(str(mask_png), example.mask.astype(np.uint8) * 255)
    return example, wavefront, mask_png


def run_json(capsys, *argv: str) -> dict:
    assert main(list(argv)) == 0
    out = capsys.readouterr().out
    return json.loads(out)


def test_example_fit_json_reports_every_documented_field(capsys) -> None:
    # the example's truth is circle Zernikes on a 3.5:1 rectangle; the default (auto) would map it
    report = run_json(capsys, "fit", "--example", "--method", "circle", "--json")
    for key in (
        "method", "modes", "ordering", "normalisation", "coefficients", "residual_rms",
        "residual_pv", "valid_pixels", "topology", "pupil", "diagnostics", "timings",
    ):
        assert key in report
    assert report["method"] == "circle" and report["modes"] == 36 and report["ordering"] == "noll"
    assert {"gram_condition", "noise_gain"} <= set(report["diagnostics"])
    example = synthetic_example()
    # White noise only: the residual RMS is the noise RMS less the fitted share (36 of ~6e4
    # samples), so it equals the noise level within its sampling scatter (~0.3 %) .
    assert report["residual_rms"] == pytest.approx(example.noise_rms, rel=0.02)
    # The fitted map departs from the truth by the projected noise: sigma * sqrt(M / N) times
    # the noise gain; allow 3x for the scatter of a single realisation.
    bound = 3 * example.noise_rms * np.sqrt(36 / report["valid_pixels"]) * report["diagnostics"]["noise_gain"]
    assert report["truth_error_rms"] < bound


def test_fit_file_with_png_mask_saves_the_fitted_map(capsys, example_files, tmp_path) -> None:
    example, wavefront, mask_png = example_files
    out = tmp_path / "fit.npy"
    report = run_json(
        capsys, "fit", str(wavefront), "--mask", str(mask_png), "--method", "qr",
        "--modes", "21", "--ordering", "ansi", "--json", "--save-fit", str(out),
    )
    fitter = build_fitter(example.mask, method="qr", modes=21, ordering="ansi", dtype=np.float64)
    expected = fitter.fit(example.wavefront)
    np.testing.assert_allclose(report["coefficients"], expected.coefficients, atol=1e-12)
    np.testing.assert_allclose(report["circle_coefficients"], expected.circle_coefficients, atol=1e-12)
    assert report["first_index"] == 0 and report["diagnostics"]["gram_condition"] == pytest.approx(1)
    saved = np.load(out)
    np.testing.assert_allclose(saved, fitter.surface(expected.coefficients), equal_nan=True)


def test_fit_with_removal_and_pupil_and_float32(capsys, example_files) -> None:
    _, wavefront, _ = example_files
    report = run_json(
        capsys, "fit", str(wavefront), "--remove", "pttp", "--pupil", "239.5,79.5,230",
        "--dtype", "float32", "--json",
    )
    assert report["dtype"] == "float32"
    assert report["pupil"] == {"cx": 239.5, "cy": 79.5, "radius": 230.0}
    assert set(report["removed"]) >= {"piston", "tilt_x", "tilt_y", "power"}


def test_human_output_lists_the_terms(capsys) -> None:
    assert main(["fit", "--example"]) == 0
    out = capsys.readouterr().out
    assert "kappa(G)" in out and "defocus" in out
    assert len([line for line in out.splitlines() if line.strip().startswith(("1 ", "36 "))]) == 2


def _one_line_error(capsys, argv: list[str], *fragments: str) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for fragment in fragments:
        assert fragment in lines[0]


def test_missing_file(capsys, tmp_path) -> None:
    _one_line_error(capsys, ["fit", str(tmp_path / "nope.npy")], "nope.npy", "no such file")


def test_wrong_dimensions(capsys, tmp_path) -> None:
    path = tmp_path / "cube.npy"
    np.save(path, np.zeros((3, 4, 5)))
    _one_line_error(capsys, ["fit", str(path)], "cube.npy", "expected a 2-D map", "(3, 4, 5)")


def test_all_nan(capsys, tmp_path) -> None:
    path = tmp_path / "nan.npy"
    np.save(path, np.full((8, 8), np.nan))
    _one_line_error(capsys, ["fit", str(path)], "nan.npy", "every value is NaN")


def test_mask_shape_mismatch(capsys, example_files, tmp_path) -> None:
    _, wavefront, _ = example_files
    mask = tmp_path / "small.npy"
    np.save(mask, np.ones((5, 5), bool))
    _one_line_error(capsys, ["fit", str(wavefront), "--mask", str(mask)], "small.npy", "does not match")


def test_not_a_npy_file(capsys, tmp_path) -> None:
    path = tmp_path / "garbage.npy"
    path.write_bytes(b"not numpy at all")
    _one_line_error(capsys, ["fit", str(path)], "garbage.npy", "not a readable .npy")


def test_nan_inside_a_given_mask(capsys, example_files, tmp_path) -> None:
    example, wavefront, _ = example_files
    mask = tmp_path / "all.npy"
    np.save(mask, np.ones(example.mask.shape, bool))  # claims the NaN pixels are valid
    _one_line_error(capsys, ["fit", str(wavefront), "--mask", str(mask)], "NaN or infinite")


@pytest.mark.parametrize("argv", [["fit", "--bogus"], ["fit"]])
def test_usage_errors_exit_2(capsys, argv) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert "usage:" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["fit", "x.npy", "--pupil", "1,2"], ["fit", "x.npy", "--modes", "0"]])
def test_a_bad_option_value_is_one_line_naming_the_option(capsys, argv) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and argv[2] in err and "usage:" not in err


def test_console_entry_point_runs_as_a_module() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "wavestack.cli", "fit", "--example", "--json", "--modes", "10"],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["modes"] == 10


def test_csf_qcm_fit_reports_map_diagnostics(capsys, tmp_path) -> None:
    from wavestack.bench.paper_apertures import annulus_circular_hole_mask

    mask = annulus_circular_hole_mask(192)
    rows, cols = np.indices(mask.shape)
    path = tmp_path / "annulus.npy"
    np.save(path, np.where(mask, 1e-4 * cols - 2e-4 * rows, np.nan))
    report = run_json(capsys, "fit", str(path), "--method", "csf-qcm", "--mesh-vertices", "4000", "--json")
    diagnostics = report["diagnostics"]
    assert report["topology"] == "doubly-connected"
    assert diagnostics["flips"] == 0 and diagnostics["max_beltrami"] < 1
    assert 0 < diagnostics["r_in"] < 1 and diagnostics["csf_iterations"] > 0
    assert {"area_scale_p5", "area_scale_p95", "p95_beltrami", "fallback"} <= set(diagnostics)
    assert any(stage.startswith("map_") for stage in report["timings"])


def test_bench_paper_prints_rows_for_one_aperture(capsys) -> None:
    assert main(["bench", "paper", "--aperture", "rounded-rectangle", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    labels = {row["label"] for row in rows}
    assert labels == {"circle", "qr", "conformal", "csf-qcm (graph)", "csf-qcm (cotangent)",
                      "csf-qcm (cotangent, balanced)"}
    by_label = {row["label"]: row for row in rows}
    assert by_label["qr"]["kappa"] == pytest.approx(1.0)
    assert by_label["csf-qcm (cotangent, balanced)"]["flips"] == 0
