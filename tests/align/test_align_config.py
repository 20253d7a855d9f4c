"""``[align]``: the shipped bench loads; wrong values name the file and the key."""

from __future__ import annotations

import tomllib

import pytest

from wavestack.config import ConfigError
from wavestack.config.align import DEFAULT_CONFIG, load_align_config, parse_align_config


def _document() -> dict:
    return tomllib.loads(DEFAULT_CONFIG.read_text(encoding="utf-8"))


def test_the_shipped_bench_loads() -> None:
    config = load_align_config()
    assert config.align.simulated and len(config.align.steps) == 5
    assert config.field_stage.axes == ("1", "2") and "U" in config.hexapod.axes
    assert abs(config.align.target_rms_waves - 1 / 14) < 1e-9


@pytest.mark.parametrize(("table", "key", "value", "words"), [
    ("align", "gain", 1.5, "gain"),
    ("align", "steps", [0.01, 0.01], "steps: expected 5 values"),
    ("align", "max_iterations", 0, "max_iterations"),
    ("align", "fit_method", "zernike", "fit_method"),
    ("field_stage", "axes", ["1", "2", "3"], "[field_stage] axes"),
    ("hexapod", "axes", ["X", "Y", "Z"], "[hexapod] axes"),
])
def test_wrong_values_name_the_key(table: str, key: str, value: object, words: str) -> None:
    document = _document()
    document[table][key] = value
    if key == "axes" and table == "hexapod":
        for name in ("soft_lower", "soft_upper", "max_step"):
            document[table][name] = document[table][name][:3]
    if key == "axes" and table == "field_stage":
        for name, extra in (("soft_lower", -1.0), ("soft_upper", 1.0), ("max_step", 1.0)):
            document[table][name] = [*document[table][name], extra]
    with pytest.raises(ConfigError, match="bench.toml") as raised:
        parse_align_config(document, source="bench.toml")
    assert words in str(raised.value)


def test_a_missing_file_is_named(tmp_path) -> None:
    with pytest.raises(ConfigError, match="absent.toml"):
        load_align_config(tmp_path / "absent.toml")
