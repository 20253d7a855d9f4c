"""The batch's pieces in this process (no Dask): planning, tasks, blocks, the fit helper, the table."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.batch import RecordingSummary, ResultsStore, analyse, fit_block, plan_recording, settings_hash
from wavestack.batch.campaign import assemble
from wavestack.batch.plan import whole_recording
from wavestack.batch.rows import ResultRow
from wavestack.pipeline import build_fitter

def test_blocks_of_a_large_recording_give_the_rows_of_one_replay(campaign, replayed_rows, comparable) -> None:
    plan = plan_recording(str(campaign.masked), None, min_block_sets=3)
    assert len(plan.tasks) == 2 and plan.tasks[0].check_next, plan  # divided where the masked optic was adopted
    outcomes = [analyse(task) for task in plan.tasks]
    assert outcomes[0].boundary_ok is True and not any(o.error for o in outcomes)
    rows, summary = assemble(plan, outcomes)
    assert [r.position for r in rows] == list(range(12)) and summary.status == "ok"
    expected = replayed_rows(campaign.masked)
    assert [comparable(r.__dict__) for r in rows] == expected
    assert {r["aperture_id"] for r in expected} == {-1, 0, 1}  # the second block's ids count on from the first's


def test_a_boundary_that_does_not_hold_is_reported_and_the_recording_redone_whole(campaign) -> None:
    plan = plan_recording(str(campaign.masked), None, min_block_sets=3)
    moved = plan.tasks[0].__class__(**{**plan.tasks[0].__dict__, "stop": plan.tasks[0].stop - 2})
    assert analyse(moved).boundary_ok is False  # no aperture adopted at that set
    whole = whole_recording(plan)
    assert (whole.start, whole.stop, whole.check_next) == (0, 12, False)


def test_fit_block_gives_what_fit_gives_map_by_map() -> None:
    yy, xx = np.mgrid[-1:1:24j, -1:1:24j]
    fitter = build_fitter(xx ** 2 + yy ** 2 <= 1, method="circle", modes=6)
    maps = np.stack([xx, yy, xx * yy])
    maps[1, 3, 12] = np.nan  # a hole in one map only: fitted on its own under the NaN policy
    batched = fit_block(fitter, maps, nan_policy="omit", residual=True)
    one_by_one = [fitter.fit(m, nan_policy="omit", residual=True) for m in maps]
    assert len(batched) == 3
    for a, b in zip(batched, one_by_one):
        np.testing.assert_allclose(a.coefficients, b.coefficients, rtol=1e-12, atol=1e-14)
        # the residual from the identity |w|^2 - c.Gc: exact to ~sqrt(eps) x |w| (here |w| ~ 1 wave)
        assert a.residual_rms == pytest.approx(b.residual_rms, rel=1e-6, abs=1e-7)


def test_other_files_are_planned_as_reported_skips(tmp_path: Path) -> None:
    align = tmp_path / "align.h5"
    with h5py.File(align, "w") as f:
        f.attrs["format"], f.attrs["version"] = "wavestack-align", 1
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.zeros(3)
    garbage = tmp_path / "garbage.h5"
    garbage.write_bytes(b"not hdf5 at all" * 10)
    for path, kind, words in ((align, "unsupported", "not a station recording"),
                              (other, "unsupported", "not a station recording"),
                              (garbage, "unreadable", "not an HDF5 file")):
        plan = plan_recording(str(path), None)
        outcome = analyse(plan.tasks[0])
        assert plan.kind == kind and words in outcome.error and not outcome.rows, (path, outcome)


def test_a_polish_campaign_record_is_refitted_map_by_map(tmp_path: Path) -> None:
    from wavestack.loop import CampaignWriter

    yy, xx = np.mgrid[-1:1:40j, -1:1:40j]
    mask = xx ** 2 + yy ** 2 <= 0.9
    path = tmp_path / "polish.h5"
    # the records a polishing campaign writes for its measurements (CampaignRecorder.measurement)
    writer = CampaignWriter(path, "wavestack-polish-campaign", "", {"shape": [40, 40], "pixel_mm": 1.0})
    surfaces = [np.where(mask, 10.0 * (2 * (xx ** 2 + yy ** 2) - 1) * k, np.nan) for k in (1.0, 2.0, 3.0)]
    for k, surface in enumerate(surfaces):
        writer.append_map(surface, units="nm", exposure_unix_s=1.0 + k, mask=mask if k == 0 else None)
    writer.close({"final_phase": "done"})
    with h5py.File(path, "r+") as f:  # the third map changed on disk: named, not refitted
        f["records/000002/map"][20, 20] = 5.0
    plan = plan_recording(str(path), None)
    assert plan.kind == "polish" and plan.sets == 2
    outcome = analyse(plan.tasks[0])
    assert not outcome.error and [r.units for r in outcome.rows] == ["nm", "nm"]
    assert len(outcome.damage) == 1 and "record 000002: CRC-32 mismatch" in outcome.damage[0]
    first, second = (np.array(r.coefficients) for r in outcome.rows)
    np.testing.assert_allclose(second, 2 * first, atol=1e-6 * np.abs(first).max())  # linear in the map


def test_settings_hash_separates_configurations_and_the_store_resumes_by_it(tmp_path: Path) -> None:
    assert settings_hash(None) != settings_hash("[processing]\nmodes = 10\n")
    store = ResultsStore(tmp_path / "out")
    assert not store.has_results() and store.done_keys() == set()
    row = ResultRow("a.h5", 0, 0, 1, (1, 2), True, "", (0.5, math.nan), "waves", 0.1, 0.2, "qr", True, "spatial", 1,
                    True, 10, "disk", 1.0, -1, math.nan, math.nan, math.nan, False)
    from wavestack.batch import RecordingSummary

    summary = RecordingSummary("a.h5", "f" * 64, "s" * 64, "station", "ok", 1, 1, 1, 0, math.nan, "", "", "",
                               0.0, 0.0, 0.0, 0.0, 0.0)
    store.write_recording("a-key", [row], summary)
    assert store.has_results() and store.done_keys() == {("f" * 64, "s" * 64)}
    table = store.read_rows().to_pylist()
    assert len(table) == 1 and table[0]["coefficients"][0] == 0.5 and math.isnan(table[0]["coefficients"][1])
    assert not list((tmp_path / "out").rglob("*.tmp"))
    (tmp_path / "out" / "summaries" / "broken.parquet").write_bytes(b"PAR1 cut")  # a crash's leftover
    assert store.done_keys() == {("f" * 64, "s" * 64)}


def test_a_summary_commits_to_its_rows_and_resume_trusts_only_those_that_agree(tmp_path: Path) -> None:
    store = ResultsStore(tmp_path / "out")
    base = RecordingSummary("a.h5", "f" * 64, "s" * 64, "station", "ok", 1, 0, 0, 0, math.nan, "", "", "",
                            0.0, 0.0, 0.0, 0.0, 0.0)
    rows = [ResultRow(recording="a.h5", position=i, index=i, time_ns=0, frame_ids=(), valid=True, reason="",
                      coefficients=(1.0,), units="waves", residual_rms=0.0, residual_pv=0.0, fitter="qr",
                      fitter_fallback=False, unwrap_path="", aperture_id=0, aperture_changed=False,
                      aperture_pixels=1, aperture_topology="disk", gram_condition=1.0, flips=0, max_beltrami=0.0,
                      difference_rms=math.nan, residual_pv_difference=math.nan, affected_by_damage=False)
            for i in range(6)]
    for name, digest in (("a", "a" * 64), ("b", "b" * 64), ("c", "c" * 64)):
        committed = store.write_recording(name, rows, dataclasses.replace(base, recording=f"{name}.h5",
                                                                          file_sha256=digest))
        assert committed.results == 6 and len(committed.rows_sha256) == 64
    assert len(store.read_rows()) == 18 and len(store.done_keys()) == 3
    (tmp_path / "out" / "results" / "a.parquet").unlink()  # deleted
    (tmp_path / "out" / "results" / "b.parquet").write_bytes(b"garbage")  # replaced
    assert store.done_keys() == {("c" * 64, "s" * 64)}  # a and b are analysed again by --resume
    assert len(store.read_rows()) == 6  # and the table never counts rows it cannot vouch for
