"""The polishing configuration: [polishing] cut from the station's tables, its keys checked in one line each."""

from __future__ import annotations

from pathlib import Path

import pytest

from shared_data import require_shared_data
from wavestack.config import ConfigError
from wavestack.config.polishing import (DEFAULT_POLISHING_CONFIG, MachineSettings, TifSettings, load_polishing_config,
                                        parse_polishing_config)

ROOT = Path(__file__).resolve().parents[2]

STATION = (Path(__file__).resolve().parents[1] / "configs" / "station-small.toml").read_text()
POLISHING = """
[polishing]
target_rms_nm = 3.0
max_runs = 5
solver = "lsq"
averaged_results = 6

[polishing.tif]
fwhm_mm = 3.5
peak_rate_nm_s = 20.0

[polishing.machine]
max_feed_mm_s = 40.0
travel_x_mm = [-50.0, 50.0]
"""


def _parse(text: str):
    return parse_polishing_config(text, source="p.toml")


def test_the_loop_and_the_station_come_apart() -> None:
    config = _parse(STATION + POLISHING)
    p = config.polishing
    assert (p.target_rms_nm, p.max_runs, p.solver, p.averaged_results) == (3.0, 5, "lsq", 6)
    assert p.tif == TifSettings(fwhm_mm=3.5, peak_rate_nm_s=20.0)
    assert p.machine.max_feed_mm_s == 40.0 and p.machine.travel_x_mm == (-50.0, 50.0)
    assert p.machine.travel_y_mm == MachineSettings().travel_y_mm  # the default
    assert "[polishing]" not in config.station.text and "[polishing]" in config.text
    assert config.station.camera_simulator.width == 256


def test_the_polishing_tables_may_come_first() -> None:
    assert _parse(POLISHING + "\n" + STATION).polishing.max_runs == 5


@pytest.mark.parametrize(("text", "words"), [
    (STATION, "missing table [polishing]"),
    (STATION + POLISHING.replace("max_runs = 5", "max_runz = 5"), "[polishing] unknown key 'max_runz'"),
    (STATION + POLISHING.replace("max_runs = 5", "max_runs = 0"), "[polishing] max_runs: expected >= 1"),
    (STATION + POLISHING.replace('solver = "lsq"', 'solver = "svd"'), "[polishing] solver: expected one of"),
    (STATION + POLISHING.replace("fwhm_mm = 3.5", 'kind = "map"'), "[polishing.tif] kind = 'map' needs file"),
    (STATION + POLISHING.replace("[-50.0, 50.0]", "[50.0, -50.0]"), "travel_x_mm: expected [lo, hi]"),
    (STATION + POLISHING.replace("averaged_results = 6", "averaged_results = 1"),
     "[polishing] averaged_results: expected >= 2"),
    (STATION.replace("fit_decimation = 1", "fit_decimation = 2") + POLISHING, "fit_decimation = 2"),
    ("polishing = { max_runs = 3 }\n" + STATION, "cannot separate"),  # an inline table: no header to cut at
    (STATION + POLISHING + "\n[polishing.bogus]\nx = 1\n", "[polishing] unknown key 'bogus'"),
    (STATION + POLISHING + "\n[bogus]\n", "unknown table [bogus]"),
])
def test_errors_are_one_line_naming_the_key(text: str, words: str) -> None:
    with pytest.raises(ConfigError) as caught:
        _parse(text)
    message = str(caught.value)
    assert words in message and message.startswith("p.toml: ") and "\n" not in message


def test_a_station_without_a_plc_is_refused() -> None:
    without_plc = STATION.split("[plc]")[0] + "\n[outputs]\nenabled = false\n"
    with pytest.raises(ConfigError, match=r"missing table \[plc\]"):
        _parse(without_plc + POLISHING)


def test_relative_files_resolve_beside_the_configuration(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    config = parse_polishing_config(STATION + POLISHING, source=str(path))
    assert config.resolve("target.npy") == tmp_path / "target.npy"
    assert config.resolve(None) is None


def test_the_default_polishing_station_is_packaged_and_loads() -> None:
    assert DEFAULT_POLISHING_CONFIG.parent.parent.name == "wavestack"  # in the package: works on a fresh machine
    config = load_polishing_config()
    surface = config.station.optic.surface
    assert surface is not None and surface.map_file is None  # Zernike + roughness: no data file needed
    assert config.station.camera_simulator.width == config.station.camera_simulator.height == 512
    assert surface.pixel_mm == config.polishing.pixel_mm and config.station.plc.simulator.machine is not None


@require_shared_data()
def test_the_zygo_polishing_station_reads_the_bundled_map() -> None:
    config = load_polishing_config(ROOT / "config" / "polishing-zygo.toml")
    assert Path(config.station.optic.surface.map_file).name == "valid_zygo_dat_file.dat"


def test_the_optic_and_the_loop_must_share_the_grid() -> None:
    text = DEFAULT_POLISHING_CONFIG.read_text(encoding="utf-8")
    changed = text.replace("edge_px = 2\nreflection_factor = 2.0", "edge_px = 2\nreflection_factor = 1.0")
    assert changed != text
    with pytest.raises(ConfigError, match=r"\[polishing\] reflection_factor = 1 differs from the simulated optic's"):
        parse_polishing_config(changed, source="p.toml")
