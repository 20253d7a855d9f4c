"""``--method annulus`` (``fit``) and ``--fit-method annulus`` (``analyze``), with ``--obscuration``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wavestack.cli import main
from wavestack.pipeline import annular_zernike_basis, build_fitter, mode_list

from shared_data import DATA, require_shared_data


@pytest.fixture()
def ring_map(tmp_path):
    """A ring of obscuration 0.4 carrying known annular terms of that obscuration about its pupil."""
    rows, cols = np.indices((100, 100), dtype=float)
    mask = np.hypot(rows - 49.5, cols - 49.5) <= 47.0
    mask &= np.hypot(rows - 49.5, cols - 49.5) >= 0.4 * 47.0
    pupil = build_fitter(mask, method="annulus", modes=1).basis  # the method's own pupil and ratio
    x = (cols[mask] - pupil.pupil.cx) / pupil.pupil.radius
    y = (pupil.pupil.cy - rows[mask]) / pupil.pupil.radius
    truth = np.array([0.0, 0.1, -0.05, 0.3, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0, 0.04])
    wavefront = np.full(mask.shape, np.nan)
    wavefront[mask] = annular_zernike_basis(mode_list("noll", 11), x, y, pupil.annular_obscuration) @ truth
    path = tmp_path / "ring.npy"
    np.save(path, wavefront)
    return path, truth, pupil.annular_obscuration


def test_fit_method_annulus_recovers_the_terms_and_reports_the_obscuration(capsys, ring_map) -> None:
    path, truth, ratio = ring_map
    assert main(["fit", str(path), "--method", "annulus", "--modes", "11", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["method"] == "annulus" and report["normalisation"] == "rms"
    assert report["annular_obscuration"] == pytest.approx(ratio, rel=1e-12) and 0.39 < ratio < 0.42
    assert report["obscuration_source"] == "measured" and report["diagnostics"]["refit"] == "moments"
    np.testing.assert_allclose(report["coefficients"], truth, atol=1e-9)
    assert main(["fit", str(path), "--method", "annulus", "--modes", "11", "--obscuration", "0.3"]) == 0
    text = capsys.readouterr().out
    assert "annulus     annular Zernike terms, unit RMS over obscuration 0.3000 (given)" in text


@pytest.mark.parametrize(("argv", "expected"), [
    (["--method", "annulus", "--obscuration", "1"], "argument --obscuration: expected a ratio of inner to outer"),
    (["--method", "annulus", "--obscuration", "nan"], "argument --obscuration: expected a ratio"),
    (["--method", "circle", "--obscuration", "0.3"], "only the 'annulus' method takes an obscuration"),
])
def test_a_bad_obscuration_is_one_line_with_status_2(capsys, ring_map, argv, expected) -> None:
    try:
        status = main(["fit", str(ring_map[0]), *argv])
    except SystemExit as usage:  # argparse's own exit for a bad option value
        status = usage.code
    assert status == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1


@require_shared_data()
def test_the_zygo_map_has_no_central_hole_so_annulus_needs_a_given_obscuration(capsys) -> None:
    # The measured map's one sizeable hole is a drop-out off the pupil centre: it is not an
    # obscuration, and the method says so instead of fitting a ring that is not there.
    path = DATA / "zygo-dat" / "valid_zygo_dat_file.dat"
    assert main(["analyze", str(path), "--fit-method", "annulus", "--modes", "15"]) == 2
    assert "no hole around the pupil centre" in capsys.readouterr().err
    assert main(["analyze", str(path), "--fit-method", "annulus", "--obscuration", "0.2", "--modes", "15",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["fit_method"] == "annulus" and report["annular_obscuration"] == 0.2
    assert report["obscuration_source"] == "given"
    assert report["pixels"]["fitted"] == report["pixels"]["measured"] - report["quality"]["clipped"]
    circle = json.loads(_run_json(capsys, ["analyze", str(path), "--fit-method", "circle", "--modes", "15"]))
    # The same 15 modes span different functions, but the fitted surface is close: the residuals agree to 10 %.
    assert report["residual_rms_waves"] == pytest.approx(circle["residual_rms_waves"], rel=0.1)


def _run_json(capsys, argv: list[str]) -> str:
    assert main([*argv, "--json"]) == 0
    return capsys.readouterr().out
