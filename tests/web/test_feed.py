"""The web view's feed: the station's records and the loops' values in, one update of the page out."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np

from wavestack.align.history import alignment_history
from wavestack.align.loop import IterationRecord
from wavestack.polish.history import campaign_history
from wavestack.polish.run_record import run_finished, run_started
from wavestack.station import (
    ApertureRecord,
    Counters,
    CycleRecord,
    FitDiagnostics,
    Heartbeat,
    OutputRecord,
    SentCommand,
    StationResult,
)
from wavestack.pipeline import SurfaceRequest, parse_form_tolerance
from wavestack.station.surface_stage import SurfaceStage
from wavestack.web import BrowserCounts, LiveFeed, update_message


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _result(index: int, coefficients: tuple[float, ...], *, valid: bool = True,
            reason: str | None = None) -> StationResult:
    base = StationResult.invalid(index, reason or "", Counters.zero(5), ordering="noll")
    return replace(base, valid=valid, reason=reason, coefficients=coefficients, residual_rms=0.01 * (index + 1),
                   residual_pv=0.1, fitter="csf-qcm", fitter_diagnostics=FitDiagnostics(3.5, 0, 0.21),
                   aperture=ApertureRecord(0, index == 0, "annulus", 1000), latency_ms=20.0 + index,
                   output=OutputRecord(Heartbeat(True, False, True, False, state="ARMED"),
                                       SentCommand(True, index, "CLIPPED", None, (1.0,))))


def _map(offset: float) -> np.ndarray:
    y, x = np.mgrid[-1:1:64j, -1:1:64j]
    return np.where(x**2 + y**2 < 1, x + offset, np.nan)


def test_the_page_shows_the_newest_result_and_the_newest_valid_coefficients() -> None:
    clock = Clock()
    feed = LiveFeed("wavestack run", clock=clock, min_render_s=0.25)
    assert feed.update().state == "waiting"
    coefficients = tuple(0.1 * j for j in range(12))
    feed(CycleRecord(_result(0, coefficients), waves=_map(0.0)))
    feed(CycleRecord(_result(1, (), valid=False, reason="residual too large")))
    update = feed.update()
    panel = update.station
    assert (update.state, panel.results, panel.valid, panel.last_index, panel.shown_index) == ("running", 2, 1, 1, 0)
    assert [(c.index, c.name) for c in panel.coefficients[:2]] == [(4, "defocus"), (5, "astigmatism 45")]
    assert [c.value for c in panel.coefficients] == list(coefficients[3:11])  # 8 after piston and tilts
    assert (panel.kappa, panel.flips, panel.max_mu) == (3.5, 0, 0.21)
    assert (panel.safety, panel.sent, panel.plc_state, panel.heartbeat_ok) == ("CLIPPED", True, "ARMED", True)
    assert panel.residual_rms == 0.01 and panel.last_reason == "residual too large"
    assert update.map is not None and update.map.title == "wavefront, result 0" and update.map.units == "waves"
    assert feed.update() is None  # nothing new


def test_maps_are_rendered_at_most_once_per_interval_and_only_the_newest() -> None:
    clock = Clock()
    feed = LiveFeed("wavestack run", clock=clock, min_render_s=0.25)
    feed(CycleRecord(_result(0, (0.0,) * 4), waves=_map(0.0)))
    assert feed.update().map.seq == 1
    for k in range(1, 6):  # five maps within the interval
        clock.now = 0.01 * k
        feed(CycleRecord(_result(k, (0.0,) * 4), waves=_map(float(k))))
        assert feed.update().map.seq == 1  # numbers go out; the picture waits
    clock.now = 0.3
    update = feed.update()
    assert update.map.seq == 6 and update.map.title == "wavefront, result 5" and update.renders == 6 - 4
    assert math.isclose(update.map.vmin, np.nanmin(_map(5.0)), abs_tol=0.1)  # the newest map, not the first waiting


def test_a_lost_device_and_the_stop_are_clear_states() -> None:
    feed = LiveFeed("wavestack run")
    feed(CycleRecord(_result(0, (0.0,) * 4)))
    feed(CycleRecord(StationResult.invalid(1, "device: camera: expected a set within 2 s", Counters.zero(5),
                                           ordering="noll")))
    assert (feed.update().state, feed.update() is None) == ("device lost", True)
    feed(CycleRecord(_result(2, (0.0,) * 4)))
    assert feed.update().state == "running"
    feed.end("stopped after 3 results")
    feed.end("the command ended")  # the first reason stays
    update = feed.update()
    assert (update.state, update.detail) == ("stopped", "stopped after 3 results")


def test_polishing_runs_and_alignment_iterations_make_the_history() -> None:
    feed = LiveFeed("wavestack polish")
    row = run_started(1, 7, rms_before_nm=40.0, pv_before_nm=200.0, noise_before_nm=0.2, predicted_rms_nm=4.0,
                      predicted_pv_nm=30.0, total_dwell_s=900.0, points=4000, job_crc32=1, started_unix_s=0.0,
                      solve_s=1.0)
    feed.loop_phase("polishing", "job 7 running")
    done = run_finished(row, measured_rms_nm=5.0, machine_state="DONE", points_done=4000, run_s=60.0)
    feed.show_history(campaign_history([row]))
    feed.show_history(campaign_history([row, done]))
    history = feed.update().history
    assert (history.kind, history.phase, history.reason) == ("polish", "polishing", "job 7 running")
    assert len(history.rows) == 1 and history.rows[0][:6] == (1, 7, 40.0, 4.0, 5.0, 8.0)  # the later row replaces
    assert history.trend == (40.0, 5.0) and len(history.columns) == len(history.rows[0])

    feed = LiveFeed("wavestack align")
    feed.show_history(alignment_history([IterationRecord(0, (0.5, 0.7)),
                                         IterationRecord(1, (0.2, 0.1), estimate=(0.1, 0.0, 0.0, 0.0, 0.0),
                                                         move={"X": -0.1})]))
    feed.show_map(_map(0.0), units="waves", title="wavefront at field point 1")
    update = feed.update()
    assert update.history.kind == "align" and update.history.trend == (0.7, 0.2)
    assert update.history.rows[1][4] == "X=-0.1000" and update.map.title == "wavefront at field point 1"
    assert update.state == "running" and update.station is None


def test_the_message_carries_the_picture_and_the_table_only_when_asked() -> None:
    feed = LiveFeed("wavestack align")
    feed.show_history(alignment_history([IterationRecord(0, (0.5, float("nan")))]))
    feed.show_map(_map(0.0), units="waves", title="field point 0")
    update = feed.update()
    full = json.loads(update_message(update, BrowserCounts(3, 1, 2, 5), with_png=True, with_history=True))
    short = json.loads(update_message(update, BrowserCounts(3, 1, 2, 5), with_png=False, with_history=False))
    assert full["map"]["png"].startswith("data:image/png;base64,") and "png" not in short["map"]
    assert full["history"]["rows"][0][0] == 0 and short["history"] == {"seq": update.history.seq}
    assert full["browser"] == {"sent": 3, "dropped": 1, "clients": 2, "dropped_all": 5}
    assert short["map"]["outline"] and short["map"]["vmin"] == full["map"]["vmin"]


def test_the_page_shows_the_surface_figures_and_the_drawings_verdict() -> None:
    # A 0.2-wave sphere of wavefront: ~63 nm of surface sagitta, about 0.2 fringes; the drawing
    # allows 0.1 fringes of power, so it fails on SAG, and the page says so with the figures.
    rows, cols = np.indices((120, 120))
    x, y = (cols - 59.5) / 55, (59.5 - rows) / 55
    waves = np.where(x * x + y * y <= 1, 0.2 * (x * x + y * y) + 0.01 * x * y, np.nan)
    request = SurfaceRequest(tolerance=parse_form_tolerance("3/0.1(0.5/0.2)"))
    record = SurfaceStage(request, wavelength_nm=632.8, surface_factor=0.5).measure(0, waves)
    feed = LiveFeed("wavestack run", clock=Clock())
    feed(CycleRecord(replace(_result(0, (0.1,) * 12), surface=record), waves=waves))
    update = feed.update()
    panel = update.station
    assert panel.surface == (record.form.irr_nm, record.form.rmst_nm, record.pvr.pvr)
    assert panel.spec == ("3/0.1(0.5/0.2)", False, "SAG") and record.verdict.limiting.quantity == "SAG"
    message = update_message(update, BrowserCounts(0, 0, 0, 0), with_png=False, with_history=False)
    station = json.loads(message)["station"]
    assert station["spec"] == ["3/0.1(0.5/0.2)", False, "SAG"] and station["surface"][1] > 0


def test_without_surface_figures_the_page_shows_none() -> None:
    feed = LiveFeed("wavestack run", clock=Clock())
    feed(CycleRecord(_result(0, (0.1,) * 12), waves=_map(0.0)))
    panel = feed.update().station
    assert panel.surface is None and panel.spec is None
