"""Refitting without some samples (a downdate of a fit) against the full refit of the same samples."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import InvalidFrame, build_fitter


def _annulus_with_obscuration(size: int = 96) -> np.ndarray:
    rows, cols = np.mgrid[:size, :size]
    centre = (size - 1) / 2
    radius = np.hypot(rows - centre, cols - centre)
    return (radius < 0.47 * size) & (np.hypot(rows - centre - 6, cols - centre + 4) > 0.12 * size)


def _case(fitter, seed: int = 4, spikes: int = 40):
    """A frame on the fitter's aperture: smooth terms, 0.01 noise, tilt, a few NaN, and spikes to drop."""
    mask = fitter.aperture.mask
    rng = np.random.default_rng(seed)
    rows, cols = np.indices(mask.shape)
    smooth = np.nan_to_num(fitter.surface(rng.normal(0.0, 0.1, fitter.n_modes)))
    frame = np.where(mask, smooth + 0.3 * cols / 50 - 0.2 * rows / 50 + rng.normal(0.0, 0.01, mask.shape), np.nan)
    inside = np.flatnonzero(mask)
    frame.reshape(-1)[inside[:5]] = np.nan  # omitted by the first fit already
    dropped = np.zeros(mask.shape, dtype=bool)
    dropped.reshape(-1)[rng.choice(inside[5:], spikes, replace=False)] = True
    frame[dropped] += rng.normal(0.0, 1.0, spikes)
    return frame, dropped


@pytest.mark.parametrize("method, remove", [("csf-qcm", "ptt"), ("qr", "pttp"), ("qr", None), ("circle", "ptt")])
def test_the_downdate_is_the_full_refit_to_rounding(method: str, remove: str | None) -> None:
    fitter = build_fitter(_annulus_with_obscuration(), method=method, modes=36, remove=remove, dtype=np.float64,
                          mesh_vertices=2000)
    frame, dropped = _case(fitter)
    fit = fitter.fit(frame, nan_policy="omit", residual=True)
    full = fitter.fit(np.where(dropped, np.nan, frame), nan_policy="omit", residual=True)
    for residual in (False, True):
        refit = fitter.refit_without(frame, fit, dropped, residual=residual)
        # float64 throughout: the downdated normal equations are the full refit's to ~1e-15 waves;
        # 1e-9 waves (6e-4 nm) is the brief's bar for "the same numbers", far above rounding.
        np.testing.assert_allclose(refit.coefficients, full.coefficients, rtol=0, atol=1e-9)
        assert refit.residual_rms == pytest.approx(full.residual_rms, rel=1e-9)
        assert refit.residual_pv == pytest.approx(full.residual_pv, rel=1e-9)
        assert (refit.valid_count, refit.nan_count) == (full.valid_count, full.nan_count)
        if remove is not None:
            assert refit.removed.piston == pytest.approx(full.removed.piston, abs=1e-9)
            assert refit.removed.tilt_x == pytest.approx(full.removed.tilt_x, abs=1e-9)
    assert refit.residual_map is not None and full.residual_map is not None
    np.testing.assert_array_equal(np.isnan(refit.residual_map), np.isnan(full.residual_map))
    np.testing.assert_allclose(refit.residual_map, full.residual_map, rtol=0, atol=1e-9)
    # and it moved: the dropped spikes made a difference much larger than the tolerance
    assert np.abs(fit.coefficients - full.coefficients).max() > 1e-4


def test_a_float32_operator_refit_agrees_to_its_own_rounding() -> None:
    fitter = build_fitter(_annulus_with_obscuration(), method="csf-qcm", modes=36, remove="ptt",
                          dtype=np.float32, mesh_vertices=2000)
    frame, dropped = _case(fitter, seed=5)
    fit = fitter.fit(frame, nan_policy="omit", residual=True)
    refit = fitter.refit_without(frame, fit, dropped)
    full = fitter.fit(np.where(dropped, np.nan, frame), nan_policy="omit", residual=True)
    # float32 products of maps of ~1 wave: ~1e-7 relative to the map, so ~1e-6 waves on the terms
    np.testing.assert_allclose(refit.coefficients, full.coefficients, rtol=0, atol=2e-6)
    assert refit.residual_rms == pytest.approx(full.residual_rms, rel=1e-4)
    assert refit.residual_pv == pytest.approx(full.residual_pv, rel=1e-4)


def test_a_fit_of_the_one_call_refit_is_downdated_too() -> None:
    rows, cols = np.mgrid[:64, :64]
    fitter = build_fitter(np.hypot(rows - 31.5, cols - 31.5) < 30, method="qr", modes=15, dtype=np.float64)
    frame = np.nan_to_num(fitter.surface(np.linspace(0.1, -0.1, 15)))
    frame[10, 30] += 3.0
    fit = fitter.fit(frame, residual=True)  # no NaN: the one-call path, which keeps no sums
    assert fit.refit_state is None
    dropped = np.zeros(frame.shape, dtype=bool)
    dropped[10, 30] = True
    refit = fitter.refit_without(frame, fit, dropped)
    np.testing.assert_allclose(refit.coefficients, np.linspace(0.1, -0.1, 15), atol=1e-12)
    # the residual's sum of squares is the first fit's less the spike's (9 waves^2): rounding leaves
    # ~1e-15 waves^2 of it, an RMS of ~5e-10 waves over these 2,800 samples
    assert refit.residual_rms < 2e-9 and refit.nan_count == 1


def test_bad_requests_are_refused_with_what_was_expected() -> None:
    rows, cols = np.mgrid[:48, :48]
    fitter = build_fitter(np.hypot(rows - 23.5, cols - 23.5) < 22, method="qr", modes=10, dtype=np.float64)
    frame = np.nan_to_num(fitter.surface(np.eye(10)[3]))
    frame[0, 0] = 0.0  # outside the aperture: never a sample
    fit = fitter.fit(frame, residual=True)
    outside = np.zeros(frame.shape, dtype=bool)
    outside[0, 0] = True
    with pytest.raises(ValueError, match="not samples the fit used"):
        fitter.refit_without(frame, fit, outside)
    with pytest.raises(ValueError, match="residual=True"):
        fitter.refit_without(frame, fitter.fit(frame), outside)
    with pytest.raises(ValueError, match="boolean map"):
        fitter.refit_without(frame, fit, outside.astype(np.uint8))
    with pytest.raises(InvalidFrame, match="fitted terms"):
        fitter.refit_without(frame, fit, np.isfinite(fit.residual_map))
