"""The live station's surface figures: the stage on the station's maps, its sub-grid and cadence, and
the [surface] table of a station file."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.config import load_station_config, parse_station_config
from wavestack.config.schema import ConfigError
from wavestack.config.station import DEFAULT_CONFIG
from wavestack.pipeline import SurfaceRequest, parse_form_tolerance
from wavestack.station.live_view import surface_line
from wavestack.station.surface_stage import SurfaceStage, surface_stage


def _waves(size: int = 200, hole: bool = True) -> np.ndarray:
    rows, cols = np.indices((size, size))
    x, y = (cols - (size - 1) / 2) / 95, ((size - 1) / 2 - rows) / 95
    inside = x * x + y * y <= 1
    if hole:
        inside &= np.hypot(x - 0.3, y) > 0.2
    return np.where(inside, 0.4 * (x * x + y * y) + 0.05 * x * y, np.nan)  # waves of wavefront


def test_figures_are_those_of_the_surface_on_the_sub_grid() -> None:
    waves = _waves()
    request = SurfaceRequest(tolerance=parse_form_tolerance("3/2(0.5/0.2)"))
    stage = SurfaceStage(request, wavelength_nm=632.8, surface_factor=0.5, max_pixels=5000)
    record = stage.measure(0, waves)
    stride = record.stride
    assert stride == int(np.ceil(np.sqrt(np.isfinite(waves).sum() / 5000))) and stride > 1
    # the sphere: 0.4 waves of wavefront at the edge = 0.2 * 632.8 nm of surface sagitta
    assert record.form.sag_nm == pytest.approx(0.4 * 632.8 * 0.5, rel=0.02)
    assert record.verdict is not None and record.verdict.limiting.quantity in ("SAG", "IRR", "RSI")
    json = record.to_json()
    assert json["spec"]["notation"] == "3/2(0.5/0.2)" and json["stride"] == stride
    assert "PASS" in surface_line(record) or "FAIL" in surface_line(record)


def test_the_analyzer_is_kept_while_the_area_stays_and_rebuilt_when_it_changes() -> None:
    stage = SurfaceStage(SurfaceRequest(), wavelength_nm=632.8, max_pixels=50000)
    stage.measure(0, _waves())
    analyzer = stage._analyzer
    stage.measure(1, _waves() * 1.1)
    assert stage._analyzer is analyzer
    stage.measure(2, _waves(hole=False))
    assert stage._analyzer is not analyzer


def test_the_psd_every_nth_result_only() -> None:
    request = SurfaceRequest(psd=True)
    stage = SurfaceStage(request, wavelength_nm=632.8, pixel_mm=0.2, max_pixels=50000, spectra_every=3)
    bands = [stage.measure(i, _waves()).band_rms_nm for i in range(6)]
    assert [b is not None for b in bands] == [True, False, False, True, False, False]


def test_a_map_that_cannot_carry_the_figures_gives_none_not_a_dead_station(caplog) -> None:
    stage = SurfaceStage(SurfaceRequest(), wavelength_nm=632.8)
    tiny = np.full((20, 20), np.nan)
    tiny[5:9, 5:9] = 0.1
    assert stage.record(0, tiny) is None
    assert stage.record(1, _waves()) is not None


def _with_surface(table: str) -> str:
    return DEFAULT_CONFIG.read_text(encoding="utf-8") + "\n[surface]\n" + table


def test_the_station_file_table() -> None:
    assert surface_stage(load_station_config(None)) is None  # off unless enabled
    config = parse_station_config(_with_surface('enabled = true\nspec = "3/1(0.5)"\npixel_mm = 0.05\npsd = true\n'),
                                  source="station.toml")
    stage = surface_stage(config)
    assert stage is not None and stage.request.tolerance.sag == 1.0 and stage.request.psd
    with pytest.raises(ConfigError, match=r"station.toml: \[surface\] spec: tolerance '3/x': at character 3"):
        parse_station_config(_with_surface('enabled = true\nspec = "3/x"\n'), source="station.toml")
    with pytest.raises(ConfigError, match=r"\[surface\] the PSD and slope need pixel_mm"):
        parse_station_config(_with_surface("enabled = true\nslope_length_mm = 1.0\n"), source="station.toml")
