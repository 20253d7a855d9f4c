"""The campaign record: runs written at hand-off and completed by a later record, measurements, events, the end."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from wavestack.figures import plot_run
from wavestack.loop import read_campaign
from wavestack.polish.measurement import average_surface
from wavestack.polish.recorder import FORMAT_NAME, CampaignRecorder, read_polish_campaign
from wavestack.polish.run_record import RunMaps, run_finished, run_line, run_started
from wavestack.station import MapSample

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


def _campaign(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A one-run campaign record; returns its mask and dwell map."""
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
    running = read_polish_campaign(path)
    assert running.runs[0].job_id == 41 and math.isnan(running.runs[0].measured_rms_nm) and running.ending is None
    assert bytes(running.run_maps[0]["job_file"]) == b"job bytes"
    done = run_finished(row, measured_rms_nm=8.0, measured_pv_nm=50.0, machine_state="DONE", points_done=1200,
                        run_s=12.0)
    recorder.run_updated(index, done, np.where(mask, 1.0, np.nan))
    recorder.close("target-met", "RMS 4 nm <= 5 nm", 1)
    recorder.close("target-met", "again", 1)  # idempotent
    return mask, dwell


def test_a_run_is_on_disk_at_hand_off_and_completed_by_a_later_record(tmp_path: Path) -> None:
    path = tmp_path / "campaign.h5"
    mask, dwell = _campaign(path)
    campaign = read_polish_campaign(path)
    assert campaign.damage == () and campaign.ending == {"final_phase": "target-met",
                                                         "final_reason": "RMS 4 nm <= 5 nm", "runs_done": 1}
    assert campaign.header["pixel_mm"] == 0.25 and campaign.header["shape"] == list(SHAPE)
    (run,) = campaign.runs
    assert run.convergence_ratio == pytest.approx(5.0) and run.machine_state == "DONE"
    assert run.job_crc32 == 0xDEADBEEF
    np.testing.assert_allclose(campaign.run_maps[0]["measured_residual_nm"][mask], 1.0)
    np.testing.assert_allclose(campaign.run_maps[0]["dwell_s"], dwell.astype(np.float32))
    np.testing.assert_array_equal(campaign.aperture_mask, mask)
    assert len(campaign.measurements) == 1 and campaign.events == (("polishing", "job 41 started"),)


def test_a_changed_record_is_named_and_the_rest_still_reads(tmp_path: Path) -> None:
    path = tmp_path / "campaign.h5"
    _campaign(path)
    log = read_campaign(path, FORMAT_NAME)
    run = next(entry for entry in log.records if entry.kind == "run")
    # change one stored dwell value on disk, as a bad sector or an editor would (the file stays valid HDF5)
    import h5py
    with h5py.File(path, "r+") as f:
        stored = f[f"records/{run.index:06d}/dwell_s"]
        values = stored[()]
        values[5, 5] += 1.0
        stored[...] = values
    campaign = read_polish_campaign(path)
    assert len(campaign.damage) == 1 and f"record {run.index:06d}: CRC-32 mismatch" in campaign.damage[0]
    # the hand-off record is lost, its completion is intact: the run still reads, without its hand-off maps
    assert campaign.runs[0].measured_rms_nm == 8.0 and "dwell_s" not in campaign.run_maps[0]
    assert campaign.ending is not None and len(campaign.measurements) == 1


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
    path = plot_run(tmp_path, _row(2), RunMaps(surface, dwell, predicted, None), pixel_mm=0.25)
    assert path.name == "run-002.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
