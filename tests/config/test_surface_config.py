"""``[optic.surface]`` in a station file: settings on load, the simulated optic's surface at start; bad values get one
line naming the key (the schema's bounds on load, the simulator's checks across keys when the starter builds it)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from wavestack.config import DEFAULT_CONFIG, load_station_config
from wavestack.config.schema import ConfigError
from wavestack.config.station import parse_station_config
from wavestack.simulated import as_simulator
from wavestack.simulators import SurfaceSettings
from wavestack.simulators.optic import OpticSettings

DEFAULT_TEXT = DEFAULT_CONFIG.read_text(encoding="utf-8")
SOURCE = "bench.toml"


def with_surface(*lines: str) -> str:
    return DEFAULT_TEXT + "\n[optic.surface]\n" + "\n".join(lines) + "\n"


def refused(text: str, source: str = SOURCE) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_station_config(text, source=source)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{source}: "), message
    return message


def refused_at_start(text: str, source: str = SOURCE) -> str:
    """A file that loads, whose optic the simulator starter refuses."""
    config = parse_station_config(text, source=source)
    with pytest.raises(ConfigError) as caught:
        as_simulator(config.optic, OpticSettings, source=source, table="optic")
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{source}: "), message
    return message


def test_default_station_has_no_surface() -> None:
    assert load_station_config().optic.surface is None


def test_surface_table_builds_the_settings() -> None:
    text = with_surface("zernike_nm = [0.0, 0.0, 0.0, 30.0, 5]", "roughness_rms_nm = 2.0",
                        "roughness_correlation_mm = 0.5", "seed = 4", "pixel_mm = 0.05", "reflection_factor = 2")
    optic = parse_station_config(text, source=SOURCE).optic
    surface = as_simulator(optic, OpticSettings, source=SOURCE, table="optic").surface
    # wavelength_nm comes from [station] (632.8 nm in the default station)
    assert surface == SurfaceSettings(zernike_nm=(0.0, 0.0, 0.0, 30.0, 5.0), roughness_rms_nm=2.0,
                                      roughness_correlation_mm=0.5, seed=4, pixel_mm=0.05, reflection_factor=2.0,
                                      wavelength_nm=632.8)


def test_station_wavelength_is_the_surface_default(tmp_path: Path) -> None:
    text = with_surface("zernike_nm = [0.0, 0.0, 0.0, 30.0]").replace("wavelength_nm = 632.8", "wavelength_nm = 543.5")
    assert parse_station_config(text, source=SOURCE).optic.surface.wavelength_nm == 543.5
    message = refused(with_surface("wavelength_nm = 600.0"))
    assert "[optic.surface] wavelength_nm = 600 does not match [station] wavelength_nm = 632.8" in message


def test_map_file_is_found_beside_the_station_file(tmp_path: Path) -> None:
    np.save(tmp_path / "figure.npy", np.ones((8, 8)))
    station = tmp_path / "station.toml"
    station.write_text(with_surface('map_file = "figure.npy"', "map_rms_nm = 40.0"), encoding="utf-8")
    surface = load_station_config(station).optic.surface
    assert Path(surface.map_file) == tmp_path / "figure.npy" and surface.map_rms_nm == 40.0
    message = refused(with_surface('map_file = "missing.npy"'), source=str(station))
    assert "[optic.surface] map_file = 'missing.npy': no such file" in message


@pytest.mark.parametrize(
    "line, pattern",
    [
        ("roughness_rms_nm = -1.0", r"\[optic.surface\] roughness_rms_nm: expected >= 0"),
        ("roughness_rms_nm = nan", r"\[optic.surface\] roughness_rms_nm: expected a finite number"),
        ('roughness_rms_nm = "2"', r"\[optic.surface\] roughness_rms_nm: expected a number"),
        ("zernike_nm = [1.0, inf]", r"\[optic.surface\] zernike_nm\[1\]: expected a finite number"),
        ("seed = -3", r"\[optic.surface\] seed: expected >= 0, got -3"),
        ("smoothness = 1", r"\[optic.surface\] unknown key 'smoothness'"),
    ],
)
def test_bad_surface_values_are_refused_naming_the_key(line: str, pattern: str) -> None:
    assert re.search(pattern, refused(with_surface(line)))


@pytest.mark.parametrize(
    "line, pattern",
    [
        ('map_file = "figure.txt"', r"\[optic.surface\] map_file: expected a .dat, .datx, .h5, .npy file"),
        ("map_rms_nm = 30.0", r"\[optic.surface\] map_rms_nm: given without map_file"),
        ("pixel_mm = 0", r"\[optic.surface\] pixel_mm: expected > 0"),
    ],
)
def test_surface_values_the_simulator_refuses_are_refused_at_start_naming_the_key(line: str, pattern: str,
                                                                                tmp_path: Path) -> None:
    (tmp_path / "figure.txt").write_text("1 2\n", encoding="utf-8")  # there, but not a map the simulator reads
    assert re.search(pattern, refused_at_start(with_surface(line), source=str(tmp_path / "station.toml")))


def test_surface_must_be_a_table() -> None:
    text = DEFAULT_TEXT.replace("seed = 1\n", 'seed = 1\nsurface = "zygo"\n', 1)
    assert "[optic.surface] expected a table" in refused(text)
