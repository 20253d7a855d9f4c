"""The [hexapod] schema: the example file loads, every inconsistency is one line naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from wavestack.config.hexapod import build_hexapod, hexapod_limits, load_hexapod_config, parse_hexapod_config
from wavestack.config.schema import ConfigError, load_toml

EXAMPLE = Path(__file__).resolve().parents[2] / "config" / "hexapod-sim.toml"


def test_the_example_loads_and_builds_a_driver() -> None:
    settings = load_hexapod_config(EXAMPLE)
    assert settings.axes == ("X", "Y", "Z", "U", "V", "W") and settings.pivot_mm == (0.0, 0.0, 0.0)
    limits = hexapod_limits(settings)
    assert limits.soft["U"] == (-0.5, 0.5) and limits.max_step["Z"] == 0.5
    driver = build_hexapod(settings)
    assert driver.configured_axes == settings.axes and not driver.is_open


def test_the_field_stage_uses_the_same_schema() -> None:
    stage = load_hexapod_config(EXAMPLE, table="field_stage")
    assert stage.axes == ("1", "2") and stage.pivot_mm is None


def base() -> dict:
    return {"url": "tcp://127.0.0.1", "axes": ["1", "2"], "soft_lower": [-1.0, -1.0], "soft_upper": [1.0, 1.0],
            "max_step": [0.5, 0.5]}


@pytest.mark.parametrize("change, key", [
    ({"soft_lower": [-1.0]}, "soft_lower"),
    ({"max_step": [0.5, 0.5, 0.5]}, "max_step"),
    ({"soft_lower": [1.0, -1.0]}, "soft_lower"),
    ({"max_step": [0.5, 0.0]}, "max_step"),
    ({"axes": ["1", "1"]}, "axes"),
    ({"axes": ["1 2", "3"]}, "axes"),
    ({"velocity": 0.0}, "velocity"),
    ({"url": "http://x"}, "url"),
    ({"pivot_mm": [0.0, 0.0]}, "pivot_mm"),
    ({"spin": 1}, "spin"),
])
def test_errors_are_one_line_naming_the_key(change, key) -> None:
    table = base() | change
    with pytest.raises(ConfigError) as caught:
        parse_hexapod_config({"hexapod": table}, source="f.toml")
    message = str(caught.value)
    assert "\n" not in message and key in message and message.startswith("f.toml: [hexapod]")


def test_a_simulator_table_is_left_to_the_simulator() -> None:
    document = load_toml(EXAMPLE)
    document["hexapod"]["simulator"] = {"anything": 1}
    assert parse_hexapod_config(document, source="x").url == "tcp://127.0.0.1:50000"


def test_missing_table_is_named() -> None:
    with pytest.raises(ConfigError, match=r"\[hexapod\]"):
        parse_hexapod_config({}, source="f.toml")
