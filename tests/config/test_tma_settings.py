"""TMA configuration: the shipped file loads, bad files fail in one line naming the file and key."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from wavestack.config.schema import ConfigError
from wavestack.config.tma import load_tma_config, parse_tma_config
from wavestack.pipeline.telescope import AsBuiltErrors

CONFIG = Path(__file__).resolve().parents[2] / "wavestack" / "config" / "tma-alignment.toml"
TEXT = CONFIG.read_text(encoding="utf-8")


def test_shipped_file_loads_with_its_design() -> None:
    design, errors = load_tma_config(CONFIG)
    assert [m.name for m in design.mirrors] == ["M1", "M2", "M3"]
    assert design.aligned_mirror == "M2" and design.pivot() == (0.0, 0.0, 500.0)
    assert design.pupil.size_mm[0] > 2 * design.pupil.size_mm[1]  # long rounded rectangle
    assert design.pupil.centre_mm[1] > design.pupil.size_mm[1]  # off-axis: clear of the axis
    assert len(design.field_points_deg) >= 3 and design.source
    assert errors == AsBuiltErrors(0.005, 0.005, 0.0005, 15)


def refused(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_tma_config(tomllib.loads(text), source="bench.toml")
    message = str(caught.value)
    assert "\n" not in message and message.startswith("bench.toml")
    return message


@pytest.mark.parametrize("old, new, pattern", [
    ("wavelength_nm = 632.8", "wavelength_nm = -1.0", r"\[tma\] wavelength_nm: expected >= 100"),
    ('aligned_mirror = "M2"', 'aligned_mirror = "M4"', r"aligned_mirror: expected one of \['M1', 'M2', 'M3'\]"),
    ("corner_radius_mm = 20.0", "corner_radius_mm = 50.0", r"pupil.corner_radius_mm: expected 0 .. 40"),
    ("pixel_mm = 1.0", "pixel_mm = 0.5", r"pixel_mm: the pupil"),
    ("field_points_deg = [[0.0, -0.6],", "field_points_deg = [[0.0, -16.0],", r"field_points_deg\[0\]"),
    ("conic = -1.350908", 'conic = "parabola"', r"\[tma.mirrors\] conic: expected a number"),
    ("tilt_deg_rms = 0.0005", "tilt_deg_rms = -1.0", r"\[tma.as_built\] tilt_deg_rms: expected >= 0"),
    ("seed = 15", "seed = 15\nsed = 3", r"unknown key 'sed'"),
    ('name = "M1"', 'name = "M3"', r"mirrors: expected distinct names"),
])
def test_bad_values_are_refused_naming_the_key(old: str, new: str, pattern: str) -> None:
    assert old in TEXT
    assert re.search(pattern, refused(TEXT.replace(old, new, 1)))


def test_missing_table_and_missing_key() -> None:
    assert "missing table [tma]" in refused("[other]\nx = 1\n")
    assert "missing required key 'image_z_mm'" in refused(re.sub(r"image_z_mm = .*\n", "", TEXT))
