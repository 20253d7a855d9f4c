"""``wavestack bench station`` runs end to end on the small simulated station and prints every figure."""

from __future__ import annotations

import json
from pathlib import Path

from wavestack.bench import STAGES, StationPathFigures, format_figures
from wavestack.cli import main

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"

FIGURE_NAMES = (
    "carrier path", "psi path", "results measured after a warm-up", "results/s", "latency p50 / p99",
    "per-result time", "set arrival", "stage ms", *STAGES, "sum of stages", "process() alone", "outside the stages", "PLC I/O",
    "hidden overhead",
    "process CPU", "simulator share", "simulator CPU ms per result", "CPU ms per result by thread", "frames",
    "aperture change", "set_aperture", "target >= 20", "target p99 <= 150 ms", "target <= 1.5", "target <= 1 s",
)


def _small_qr_config(tmp_path: Path) -> Path:
    # The small station with the qr fitter: it is built at once, so neither the warm-up nor the
    # aperture change waits seconds for a csf-qcm map; every figure is still measured and printed.
    text = SMALL.read_text(encoding="utf-8")
    assert 'fit_method = "csf-qcm"' in text
    path = tmp_path / "station-small-qr.toml"
    path.write_text(text.replace('fit_method = "csf-qcm"', 'fit_method = "qr"'), encoding="utf-8")
    return path


def test_bench_station_runs_both_paths_and_prints_every_figure(tmp_path, capsys) -> None:
    config = _small_qr_config(tmp_path)
    assert main(["bench", "station", "--config", str(config), "--results", "3", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["benchmark"] == "station" and set(report["targets"]) >= {"carrier_results_per_s_min"}
    assert [path["path"] for path in report["paths"]] == ["carrier", "psi"]
    figures = [StationPathFigures(**path) for path in report["paths"]]  # every field, nothing more
    for f in figures:
        assert f.results == 3 and set(f.stage_ms) == set(STAGES) == set(f.alone_stage_ms)
    text = "\n".join(format_figures(str(config), figures))
    missing = [name for name in FIGURE_NAMES if name not in text]
    assert not missing, f"figures not printed: {missing}\n{text}"
    assert text.count("3 results measured") == 2  # both paths say over how many results
