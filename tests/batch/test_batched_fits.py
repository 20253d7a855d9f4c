"""The batched refit: prepare each set, fit the maps that share a fitter with ``Fitter.fit_many``,
finish each; the same results as set by set to the float32 operator's rounding, and blocks of a
recording fitted exactly as the whole recording is."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.batch import analyse, plan_recording, settings_hash
from wavestack.batch.campaign import assemble
from wavestack.pipeline import Fitter
from wavestack.recording import RecordingReader, recorded_config, replay
from wavestack.recording.replay import ReplayedResult


def _replayed(path, batched_fits: bool) -> list[ReplayedResult]:
    with RecordingReader(path) as reader:
        return [r for r in replay(reader, recorded_config(reader, path), same_settings=True, batched_fits=batched_fits)
                if isinstance(r, ReplayedResult)]


def test_the_batched_path_equals_the_one_by_one_path_on_a_recording(campaign, monkeypatch) -> None:
    stacks: list[int] = []
    original = Fitter.fit_many

    def counted(self, frames, **kwargs):
        stacks.append(len(frames))
        return original(self, frames, **kwargs)

    one_by_one = _replayed(campaign.masked, batched_fits=False)
    assert not stacks  # the live station's path: no batch
    monkeypatch.setattr(Fitter, "fit_many", counted)
    batched = _replayed(campaign.masked, batched_fits=True)
    # the masked recording: an aperture, a change, a second aperture; qr stand-ins, then csf-qcm
    assert stacks and max(stacks) > 1 and sum(stacks) <= sum(r.processed.valid for r in batched)
    assert [r.index for r in batched] == [r.index for r in one_by_one]
    for a, b in zip(one_by_one, batched):
        p, q = a.processed, b.processed
        assert (q.valid, q.reason, q.fitter_kind, q.unwrap_path, q.aperture_changed) == \
               (p.valid, p.reason, p.fitter_kind, p.unwrap_path, p.aperture_changed), a.index
        assert (q.choice is None) == (p.choice is None)
        if p.choice is not None:
            assert q.choice.aperture_id == p.choice.aperture_id
        if p.valid:
            # float32 operator: one product per stack rounds otherwise than one per map (measured 7e-7)
            np.testing.assert_allclose(q.coefficients_waves, p.coefficients_waves, rtol=0, atol=5e-6)
            # the RMS from |w|^2 - c.Gc in float32: exact to ~sqrt(eps32) |w| (measured 5e-5 waves)
            assert q.residual_rms == pytest.approx(p.residual_rms, abs=5e-4)
            assert q.residual_pv == pytest.approx(p.residual_pv, abs=5e-5)


def test_blocks_with_batched_fits_give_the_rows_of_one_batched_replay(campaign, replayed_rows, comparable) -> None:
    plan = plan_recording(str(campaign.masked), None, min_block_sets=3, batched_fits=True)
    assert len(plan.tasks) == 2 and all(t.batched_fits for t in plan.tasks)
    outcomes = [analyse(task) for task in plan.tasks]
    assert outcomes[0].boundary_ok is True and not any(o.error for o in outcomes)
    rows, _ = assemble(plan, outcomes)
    assert [comparable(r.__dict__) for r in rows] == replayed_rows(campaign.masked, batched_fits=True)


def test_batched_fits_are_other_settings_for_resume() -> None:
    assert settings_hash(None, batched_fits=True) != settings_hash(None)
    assert settings_hash("[processing]", batched_fits=True) != settings_hash(None, batched_fits=True)
