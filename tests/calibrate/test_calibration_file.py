"""A calibration written by ``calibrate rotation --out`` and used live: ``run --calibration`` subtracts it, every
result and the recording name its hash; a calibration of another grid or a damaged file is refused with the reason."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.cli import main
from wavestack.cli.calibrate import CALIBRATION_STATION
from wavestack.config.rotation_stage import DEFAULT_ROTATION_STAGE
from wavestack.pipeline.calibration import read_calibration
from shared_data import DATA

WAVELENGTH_NM = 632.8


@pytest.fixture(scope="module")
def calibration_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cal") / "cal.h5"
    assert main(["calibrate", "rotation", "--positions", "4", "--maps", "4", "--settle-s", "0",
                 "--out", str(path), "--json"]) == 0
    return path


def _results(text: str) -> list[dict]:
    return [row for row in map(json.loads, text.splitlines()) if row.get("type") == "result"]


def test_run_subtracts_the_calibration_and_every_result_and_the_recording_name_it(
        calibration_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    calibration = read_calibration(calibration_file)
    assert calibration.method == "rotation" and calibration.grid == (128, 128) and calibration.unresolved_orders == (0, 4)
    record = tmp_path / "run.h5"
    assert main(["run", "--config", str(CALIBRATION_STATION), "--calibration", str(calibration_file), "--frames", "4",
                 "--json", "--record", str(record)]) == 0
    results = [r for r in _results(capsys.readouterr().out) if r["valid"]]
    assert results and all(r["calibration"] == calibration.digest for r in results)
    # the simulator's truth of a calibrated map is the part alone; what is left is the reference's unresolved
    # orders 0 and 4 (4.5 nm RMS of the 20 nm, Noll 14 and 15 of the station's reference) and noise: far below
    # the 20 nm (0.032 waves) a map that kept the reference would show against that truth
    worst = max(r["truth_error_rms"] for r in results)
    assert worst * WAVELENGTH_NM < 6.0, worst
    with h5py.File(record, "r") as file:
        assert file["conventions"].attrs["calibration_sha256"] == calibration.digest


def test_a_calibration_of_another_grid_or_a_tampered_one_is_refused_before_any_device(
        calibration_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["run", "--calibration", str(calibration_file), "--frames", "1"]) == 2  # the 1024 x 1024 station
    assert "128 x 128 camera grid, the frames are 1024 x 1024" in capsys.readouterr().err
    tampered = tmp_path / "tampered.h5"
    tampered.write_bytes(calibration_file.read_bytes())
    with h5py.File(tampered, "r+") as file:
        file["reference_waves"][64, 64] = np.float64(file["reference_waves"][64, 64]) + 0.01
    assert main(["run", "--config", str(CALIBRATION_STATION), "--calibration", str(tampered), "--frames", "1"]) == 2
    assert "changed or damaged since it was written" in capsys.readouterr().err
    assert main(["calibrate", "rotation", "--out", str(calibration_file)]) == 2  # never overwritten
    assert "exists already" in capsys.readouterr().err


def test_a_stage_that_refuses_a_position_fails_the_command_and_writes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stage = tmp_path / "stage.toml"
    text = DEFAULT_ROTATION_STAGE.read_text(encoding="utf-8").replace("soft_upper = [370.0]", "soft_upper = [150.0]")
    stage.write_text(text, encoding="utf-8")
    out = tmp_path / "cal.h5"
    assert main(["calibrate", "rotation", "--stage", str(stage), "--maps", "3", "--settle-s", "0",
                 "--out", str(out)]) == 3
    error = capsys.readouterr().err
    assert "position 3 of 4 (180 deg): the rotation stage:" in error and "nothing written" in error, error
    assert not out.exists() and list(tmp_path.iterdir()) == [stage]


def test_analyze_subtracts_the_calibration_from_a_set_of_the_calibrated_grid(
        calibration_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import cv2

    from wavestack.config.station import load_station_config
    from wavestack.simulated import as_simulator
    from wavestack.simulators.optic import OpticSettings, TestOptic

    config = load_station_config(CALIBRATION_STATION)
    optic = TestOptic(as_simulator(config.optic, OpticSettings, source="calibration", table="optic"), 128, 128)
    frames = []
    for k in range(5):  # the station's hariharan steps
        path = tmp_path / f"frame{k}.png"
        cv2.imwrite(str(path), optic.interferogram(0.0, k * np.pi / 2)[0])
        frames.append(str(path))
    common = ["analyze", *frames, "--config", str(CALIBRATION_STATION), "--json"]
    capsys.readouterr()
    assert main([*common, "--save-map", str(tmp_path / "plain.npy")]) == 0
    assert "calibration_sha256" not in json.loads(capsys.readouterr().out)
    assert main([*common, "--calibration", str(calibration_file), "--save-map", str(tmp_path / "cal.npy")]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["calibration_sha256"] == read_calibration(calibration_file).digest
    removed = np.load(tmp_path / "plain.npy") - np.load(tmp_path / "cal.npy")
    # what left the map is the calibration's reference (18.5 nm RMS separated of the 19.9 nm), tilt and piston aside
    spread = np.nanstd(removed) * WAVELENGTH_NM
    assert 17.0 < spread < 20.0, spread
    assert main(["analyze", str(DATA / "zygo-dat" / "valid_zygo_dat_file.dat"),
                 "--calibration", str(calibration_file)]) == 2
    assert "--calibration applies to interferograms of the calibrated camera grid" in capsys.readouterr().err
