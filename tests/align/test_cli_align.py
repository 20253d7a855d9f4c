"""``wavestack align`` as a user runs it: options, the default simulated bench, JSON lines and the record."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from wavestack.align.recorder import read_alignment
from wavestack.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]


def _main(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    try:
        status = main(["align", *args])
    except SystemExit as stopped:
        status = int(stopped.code or 0)
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_align_is_a_command_with_its_options() -> None:
    args = build_parser().parse_args(["align", "--config", "b.toml", "--max-iterations", "3",
                                      "--target-rms-waves", "0.05", "--json", "--record", "a.h5"])
    assert (args.command, args.max_iterations, args.target_rms_waves, args.json) == ("align", 3, 0.05, True)


@pytest.mark.parametrize(("args", "words"), [
    (["--max-iterations", "0"], "--max-iterations"),
    (["--target-rms-waves", "-1"], "--target-rms-waves"),
    (["--config", "/nonexistent/bench.toml"], "/nonexistent/bench.toml"),
])
def test_bad_options_exit_2(capsys: pytest.CaptureFixture[str], args: list[str], words: str) -> None:
    status, _, err = _main(capsys, *args)
    assert status == 2 and words in err


def test_the_shipped_alignment_station_validates() -> None:
    from wavestack.config.station import load_station_config
    config = load_station_config(ROOT / "wavestack" / "config" / "tma-alignment-station.toml")
    assert (config.camera_simulator.height, config.camera_simulator.width) == (128, 256)


def test_one_iteration_prints_json_and_records(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    record = tmp_path / "align.h5"
    status, out, _ = _main(capsys, "--max-iterations", "1", "--json", "--record", str(record))
    lines = [json.loads(line) for line in out.splitlines()]
    assert status == 0
    assert [line["type"] for line in lines] == ["iteration", "iteration", "summary"]
    first, second, summary = lines
    assert set(first["estimate"]) == {"X", "Y", "Z", "U", "V"} and first["move"] and first["read_back"]
    assert max(second["rms_waves"]) < max(first["rms_waves"]) / 3  # one correction at gain 0.9
    assert summary["final_phase"] in ("max-iterations", "target-met")
    recorded = read_alignment(record)
    assert recorded.damage == () and recorded.ending["final_phase"] == summary["final_phase"]
    assert [r.iteration for r in recorded.iterations] == [0, 1]
    assert len(recorded.iterations[0].move) == 5 and len(recorded.iterations[0].read_back) == 6
    assert recorded.events[0][0] == "moving-field" and recorded.events[-1][0] == summary["final_phase"]
