"""``wavestack polish`` as a user runs it: paths and configuration checked before any device, then a real campaign."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from polishing_stations import polishing_text
from wavestack.cli import build_parser, main

WAVESTACK = [sys.executable, "-m", "wavestack.cli"]


def _run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*WAVESTACK, *args], capture_output=True, text=True, timeout=timeout)


def test_polish_is_a_command_with_its_options() -> None:
    args = build_parser().parse_args(["polish", "--target-rms-nm", "3", "--max-runs", "2", "--solver", "lsq",
                                      "--json", "--record", "c.h5", "--plots", "figs"])
    assert (args.command, args.target_rms_nm, args.max_runs, args.solver, args.json) == ("polish", 3.0, 2, "lsq",
                                                                                         True)


def _main(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """``wavestack polish ARGS`` in this process: (exit status, standard error)."""
    try:
        status = main(["polish", *args])
    except SystemExit as stopped:  # argparse's usage errors
        status = int(stopped.code or 0)
    return status, capsys.readouterr().err


@pytest.mark.parametrize(("args", "words"), [
    (["--max-runs", "0"], "--max-runs: expected a positive integer"),
    (["--target-rms-nm", "nan"], "--target-rms-nm: expected a finite number >= 0"),
    (["--solver", "svd"], "invalid choice"),
])
def test_bad_options_exit_2(capsys: pytest.CaptureFixture[str], args: list[str], words: str) -> None:
    status, err = _main(capsys, *args)
    assert status == 2 and words in err


def test_paths_and_configuration_are_checked_before_any_device(capsys: pytest.CaptureFixture[str],
                                                              tmp_path: Path) -> None:
    existing = tmp_path / "c.h5"
    existing.write_bytes(b"")
    not_a_folder = tmp_path / "figs"
    not_a_folder.write_text("")
    bad_config = tmp_path / "p.toml"
    bad_config.write_text(polishing_text().replace("max_runs = 4", "max_runs = -1"))
    cases = [
        (["--record", str(existing)], "refusing to overwrite"),
        (["--record", str(tmp_path / "missing" / "c.h5")], "does not exist"),
        (["--plots", str(not_a_folder)], "not a folder"),
        (["--config", str(bad_config)], "[polishing] max_runs: expected >= 1"),
        (["--config", str(tmp_path / "absent.toml")], "no such configuration file"),
    ]
    for args, words in cases:
        status, err = _main(capsys, *args)
        assert status == 2, (args, err)
        assert words in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
def test_a_campaign_prints_records_and_draws_every_run(tmp_path: Path) -> None:
    config = tmp_path / "polishing.toml"
    config.write_text(polishing_text(small=True))
    record, plots = tmp_path / "campaign.h5", tmp_path / "figs"
    done = _run("polish", "--config", str(config), "--max-runs", "1", "--target-rms-nm", "0", "--json",
                "--record", str(record), "--plots", str(plots))
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert [line["type"] for line in lines] == ["run", "summary"]
    run, summary = lines
    assert run["run"] == 1 and run["machine_state"] == "DONE" and run["points_done"] == run["points"]
    assert run["measured_rms_nm"] < run["rms_before_nm"] and run["convergence_ratio"] > 1
    assert summary["final_phase"] == "max-runs" and summary["job_ids"] == [run["job_id"]]
    assert len(summary["rms_nm"]) == 2
    with h5py.File(record, "r") as f:
        assert f.attrs["final_phase"] == "max-runs" and f["runs/job_id"][0] == run["job_id"]
        assert f["runs/job_crc32"][0] == run["job_crc32"] and f["measurements/rms_nm"].shape == (2,)
    assert (plots / "run-001.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_a_campaign_stops_when_the_drawing_is_met_and_names_the_limiting_quantity(tmp_path: Path) -> None:
    config = tmp_path / "polishing.toml"
    config.write_text(polishing_text(small=True))
    # the simulated part (about 50 nm RMS) is within 5 fringes everywhere: met on the first
    # measurement, no job sent, whatever the RMS target says
    done = _run("polish", "--config", str(config), "--max-runs", "2", "--target-rms-nm", "0", "--json",
                "--spec", "3/5(5/5; RMSi < 1)")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout.splitlines()[-1])
    assert summary["final_phase"] == "target-met" and summary["runs_done"] == 0 and summary["job_ids"] == []
    assert summary["spec"]["passed"] is True and summary["spec"]["limiting"] in ("SAG", "IRR", "RSI", "RMSi")
    assert "3/5(5/5; RMSi < 1): PASS, limiting" in summary["reason"]
