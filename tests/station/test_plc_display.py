"""The machine's panel on a live station: the simulated PLC's display block, read over Modbus by a
third party after each result, holds that result's validity, residual RMS, PVr and the drawing's
verdict; a lost camera's result shows invalid; what the station's result says is the reference."""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path

import pytest
from plc_panel import read_panel
from pymodbus.client import ModbusTcpClient

from wavestack.config import load_station_config
from wavestack.station import CycleRecord, StationResult

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
SPEC = "3/1(0.5/0.2)"
LIMITING_CODES = {"SAG": 1, "IRR": 2, "RSI": 3, "RMSt": 4, "RMSi": 5, "RMSa": 6}  # docs/instruments.md


def test_the_panel_shows_each_result_as_the_station_made_it(station_factory) -> None:
    config = load_station_config(SMALL)
    assert config.plc is not None
    # a generous watchdog and result age: this test is about what the panel shows, not about a loaded machine
    plc = replace(config.plc, link=replace(config.plc.link, watchdog_timeout_s=20.0))
    config = replace(config, plc=plc, station=replace(config.station, max_result_age_s=20.0),
                     surface=replace(config.surface, enabled=True, spec=SPEC, max_pixels=4000))  # a cheap sub-grid
    station, devices = station_factory(config)
    sim = devices.plc_simulator
    address = config.plc.link.display_register
    assert address is not None
    camera = devices.bench.camera
    replug = threading.Timer(0.6, camera.replug)
    client = ModbusTcpClient(sim.host, port=sim.port, timeout=2.0, retries=0)
    assert client.connect()
    seen: list[tuple[StationResult, dict[str, object]]] = []

    def on_result(record: CycleRecord) -> None:
        seen.append((record.result, read_panel(client, address)))  # after the cycle's writes, before the next
        if record.result.index == 3:
            camera.unplug()
            replug.start()

    try:
        station.run(stop=threading.Event(), on_result=on_result, max_results=9)
    finally:
        replug.cancel()
        replug.join()
    try:
        after = read_panel(client, address)
    finally:
        client.close()
    assert after == seen[-1][1]  # the panel keeps the last result after the run
    surface_nm_per_wave = config.station.wavelength_nm * config.surface.surface_factor
    judged = invalid = 0
    for result, panel in seen:
        assert result.output is not None and result.output.displayed is True, result.output
        assert panel["counter"] == result.index % 65536 and panel["valid"] == result.valid
        if not result.valid:
            invalid += 1
            # invalid: no figures, and a station with a drawing says "not judged", never "no spec"
            assert (panel["figures"], panel["rms_nm"], panel["pvr_nm"], panel["spec"], panel["limiting"]) == (
                False, 0.0, 0.0, 3, 0)
            continue
        # float32 on the wire: 2**-24 relative rounding
        assert panel["rms_nm"] == pytest.approx(result.residual_rms * surface_nm_per_wave, rel=1e-6)
        assert result.surface is not None and result.surface.verdict is not None
        verdict = result.surface.verdict
        assert panel["figures"] and panel["pvr_nm"] == pytest.approx(result.surface.pvr.pvr, rel=1e-6)
        assert panel["spec"] == (1 if verdict.passed else 2)
        assert panel["limiting"] == LIMITING_CODES[verdict.limiting.quantity]
        judged += 1
    assert judged >= 3 and invalid >= 1, [(r.index, r.valid, r.reason) for r, _ in seen]
