"""The terms, the sensitivity matrix, the estimate and the correction, on small exact cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from tma_helpers import example
from wavestack.align import TermFitter, estimate_state, plan_move
from wavestack.pipeline.telescope import DOFS, HexapodPose, Sensitivity, TmaModel, build_sensitivity

SOFT = {"X": (-5.0, 5.0), "Y": (-5.0, 5.0), "Z": (-2.0, 2.0), "U": (-0.5, 0.5), "V": (-0.5, 0.5)}
STEP = {"X": 0.5, "Y": 0.5, "Z": 0.5, "U": 0.05, "V": 0.05}


@pytest.mark.parametrize("method", ["csf-qcm", "circle"])
def test_fitter_recovers_terms_on_the_pupil(method: str) -> None:
    design, _ = example()
    fitter = TermFitter(TmaModel(design).pupil_mask, 15, method=method)
    truth = np.random.default_rng(3).normal(0.0, 0.2, fitter.count)
    assert np.allclose(fitter.terms(fitter.synthesise(truth)), truth, atol=1e-9)
    with pytest.raises(ValueError, match="non-finite"):
        fitter.terms(np.full(fitter.mask.shape, np.nan))


def test_the_default_fitter_is_csf_qcm_and_differs_from_the_circle() -> None:
    """The CSF-QCM basis is not the circle's: the same map gives other terms (one basis per loop)."""
    design, _ = example()
    mask = TmaModel(design).pupil_mask
    csf, circle = TermFitter(mask, 11), TermFitter(mask, 11, method="circle")
    assert csf.method == "csf-qcm"
    w = circle.synthesise(np.eye(10)[2])  # circle defocus
    assert np.linalg.norm(csf.terms(w) - circle.terms(w)) > 0.05
    with pytest.raises(ValueError, match="method"):
        TermFitter(mask, 11, method="zernike")


def test_sensitivity_predicts_a_small_misalignment() -> None:
    """The linear model from central differences predicts the model's terms for a small pose."""
    design, _ = example()
    model = TmaModel(design)
    fitter = TermFitter(model.pupil_mask, 15)
    fields = design.field_points_deg
    scales = np.array([0.1, 0.1, 0.1, 0.01, 0.01])
    s = build_sensitivity(model.wavefront, fields, fitter, at=np.zeros(5), steps=scales / 10, scales=scales)
    state = np.array([0.02, -0.01, 0.015, 0.002, -0.001])
    pose = HexapodPose(*state, 0.0)
    actual = np.concatenate([fitter.terms(model.wavefront(f, pose)) for f in fields])
    predicted = s.nominal + s.matrix @ (state / scales)
    # second-order terms of a 0.02 mm / 0.002 deg pose: under 2 % of the change
    assert np.linalg.norm(actual - predicted) < 0.02 * np.linalg.norm(actual - s.nominal)
    assert np.linalg.matrix_rank(s.matrix, tol=1e-6 * np.linalg.norm(s.matrix)) == len(DOFS)
    recovered = estimate_state(s, actual)
    assert np.allclose(recovered.state, state, rtol=0.05, atol=2e-4)


def test_truncation_drops_an_unseen_direction() -> None:
    matrix = np.zeros((6, 5))
    matrix[:5, :5] = np.diag([1.0, 1.0, 1.0, 1.0, 1e-6])
    s = Sensitivity(matrix, np.zeros(6), np.zeros(5), np.ones(5))
    est = estimate_state(s, np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0]), rcond=1e-3)
    assert est.kept == 4 and est.state[4] == 0.0  # a direction the data cannot see is not moved


@fuzz_settings(200)
@given(current=st.lists(st.floats(-0.4, 0.4), min_size=5, max_size=5),
       state=st.lists(st.floats(-50.0, 50.0), min_size=5, max_size=5), gain=st.floats(0.01, 1.0))
def test_no_move_exceeds_the_step_or_the_limits(current, state, gain) -> None:
    now = dict(zip(DOFS, current))
    move = plan_move(now, np.array(state), gain=gain, max_step=STEP, soft=SOFT)
    for axis in DOFS:
        assert SOFT[axis][0] <= move.target[axis] <= SOFT[axis][1]
        assert abs(move.target[axis] - now[axis]) <= STEP[axis]
    if move.scale == 1.0 and not move.clipped:  # a correction within the step is applied as asked
        assert np.allclose([move.step[a] for a in DOFS], -gain * np.array(state), atol=1e-9)
