"""The campaign record: runs written at hand-off and completed in place, measurements, events, the end."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.polish.measurement import MapSample, average_surface
from wavestack.polish.plots import plot_run
from wavestack.polish.recorder import FORMAT_NAME, CampaignRecorder
from wavestack.polish.run_record import run_finished, run_line, run_started

SHAPE = (20, 24)


def _row(run: int = 1):
    return run_started(run, 40 + run, rms_before_nm=40.0, pv_before_nm=210.0, noise_before_nm=0.3,
                       predicted_rms_nm=4.0, predicted_pv_nm=30.0, total_dwell_s=900.0, points=1200,
                       job_crc32=0xDEADBEEF, started_unix_s=1.5, solve_s=0.5)


def _maps(seed: int = 0):
    rng = np.random.default_rng(seed)
    mask = np.zeros(SHAPE, bool)
    mask[3:17, 4:20] = True
    surface = np.where(mask, rng.normal(0, 10, SHAPE), np.nan)
    return mask, surface, np.abs(rng.normal(0, 1, SHAPE)), np.where(mask, rng.normal(0, 1, SHAPE), np.nan)


def test_a_run_is_on_disk_at_hand_off_and_completed_in_place(tmp_path: Path) -> None:
    path = tmp_path / "campaign.h5"
    mask, surface, dwell, predicted = _maps()
    recorder = CampaignRecorder(path, SHAPE, "[polishing]\n", {"pixel_mm": 0.25})
    waves = np.where(mask, 0.01, np.nan)
    measurement = average_surface([MapSample(waves, True, None, 0, 10**9)] * 2, wavelength_nm=600.0,
                                  reflection_factor=2.0, min_count=2)
    assert recorder.measurement(measurement) == 0
    row = _row()
    index = recorder.run_started(row, measured_nm=surface, dwell_s=dwell, predicted_residual_nm=predicted,
                                 job_file=b"job bytes")
    recorder.event("polishing", "job 41 started")
    # readable while the campaign goes on: the run is there, its result not yet
    with h5py.File(path, "r", locking=False) as f:
        assert f["runs/job_id"][index] == 41 and math.isnan(f["runs/measured_rms_nm"][index])
        assert bytes(f["runs/job_file"][index]) == b"job bytes"
    done = run_finished(row, measured_rms_nm=8.0, measured_pv_nm=50.0, machine_state="DONE", points_done=1200,
                        run_s=12.0)
    after = np.where(mask, 1.0, np.nan)
    recorder.run_updated(index, done, after)
    recorder.close("target-met", "RMS 4 nm <= 5 nm", 1)
    recorder.close("target-met", "again", 1)  # idempotent
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == FORMAT_NAME and f.attrs["final_phase"] == "target-met"
        assert f.attrs["runs_done"] == 1 and f.attrs["pixel_mm"] == 0.25
        assert f["runs/convergence_ratio"][0] == pytest.approx(5.0)
        assert f["runs/machine_state"][0].decode() == "DONE"
        assert f["runs/job_crc32"][0] == 0xDEADBEEF
        np.testing.assert_allclose(f["runs/measured_residual_nm"][0][mask], 1.0)
        np.testing.assert_allclose(f["runs/dwell_s"][0], dwell.astype(np.float32))
        np.testing.assert_array_equal(f["aperture_mask"][()], mask)
        assert f["measurements/count"][0] == 2
        assert f["events/text"][0].decode() == "polishing: job 41 started"


def test_refuses_a_map_of_another_shape_and_an_unknown_run(tmp_path: Path) -> None:
    recorder = CampaignRecorder(tmp_path / "c.h5", SHAPE, "", {})
    try:
        with pytest.raises(ValueError, match="expected a"):
            recorder.run_started(_row(), measured_nm=np.zeros((3, 3)), dwell_s=np.zeros(SHAPE),
                                 predicted_residual_nm=np.zeros(SHAPE), job_file=b"")
        with pytest.raises(IndexError):
            recorder.run_updated(0, _row())
    finally:
        recorder.close("faulted", "test", 0)


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    (tmp_path / "c.h5").write_bytes(b"")
    with pytest.raises(OSError):
        CampaignRecorder(tmp_path / "c.h5", SHAPE, "", {})


def test_json_and_line_of_a_run() -> None:
    row = _row()
    record = row.to_json()
    assert record["type"] == "run" and record["measured_rms_nm"] is None  # NaN -> null
    json.dumps(record, allow_nan=False)
    assert set(record) - {"type"} == {f.name for f in dataclasses.fields(row)}
    assert "measured -" in run_line(row) and "predicted 4.00" in run_line(row)
    done = run_finished(row, measured_rms_nm=10.0, measured_pv_nm=60.0, machine_state="ABORTED",
                        points_done=300, run_s=3.0)
    assert "ratio 4.00" in run_line(done) and "ABORTED 300/1200" in run_line(done)


def test_plot_of_a_run_is_a_png(tmp_path: Path) -> None:
    mask, surface, dwell, predicted = _maps(1)
    path = plot_run(tmp_path, _row(2), measured_nm=surface, dwell_s=dwell, predicted_residual_nm=predicted,
                    measured_residual_nm=None, pixel_mm=0.25)
    assert path.name == "run-002.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
