"""A station with ``[surface]`` on records each result's surface figures and the drawing's verdict,
the same figures its JSON lines print."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from wavestack.cli import main
from wavestack.recording import RecordingReader

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"


def test_recorded_surface_columns_are_the_printed_figures(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config = tmp_path / "station.toml"
    config.write_text(SMALL.read_text(encoding="utf-8") + '\n[surface]\nenabled = true\nspec = "3/1(0.5/0.2)"\n',
                      encoding="utf-8")
    path = tmp_path / "run.h5"
    assert main(["run", "--config", str(config), "--frames", "4", "--json", "--record", str(path)]) == 0
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    by_index = {line["index"]: line for line in printed if "index" in line and line.get("valid")}
    assert by_index, printed
    with RecordingReader(path) as reader:
        table = reader.results()
    for row, index in enumerate(table["index"]):
        line = by_index.get(int(index))
        if line is None or line.get("surface") is None:
            assert table["spec_passed"][row] == -1 and math.isnan(table["surface_irr_nm"][row])
            continue
        surface = line["surface"]
        for key, name in (("sag", "SAG"), ("irr", "IRR"), ("rsi", "RSI"), ("rmst", "RMSt")):
            assert table[f"surface_{key}_nm"][row] == pytest.approx(surface["nm"][name], rel=1e-12)
        assert table["surface_pvr_nm"][row] == pytest.approx(surface["pvr_nm"], rel=1e-12)
        assert table["spec_passed"][row] == int(surface["spec"]["passed"])
        assert table["spec_limiting"][row] == surface["spec"]["limiting"]
    assert np.isin(table["spec_passed"], [0, 1]).sum() >= 1  # at least one result carried the verdict
