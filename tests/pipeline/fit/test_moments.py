"""The moment refit against the operator refit of the same basis: the same FitResult."""

from __future__ import annotations

import numpy as np
import pytest
from fuzz import fuzz_settings
from moment_pairs import assert_same_fit, moments_match_or_refuse
from hypothesis import assume, given
from hypothesis import strategies as st

from wavestack.pipeline import build_fitter, mode_list
from wavestack.pipeline.fit.store import load_fitter, save_fitter


def _mask(kind: str, size: int, rng: np.random.Generator) -> np.ndarray:
    rows, cols = np.indices((size, size), dtype=float)
    cy, cx = (size - 1) / 2 + rng.uniform(-2, 2, 2)
    radius = size * rng.uniform(0.36, 0.48)
    r = np.hypot(rows - cy, cols - cx)
    if kind == "disk":
        return r <= radius
    if kind == "annulus":
        return (r <= radius) & (r >= radius * rng.uniform(0.15, 0.5))
    if kind == "ellipse":
        return ((rows - cy) / (radius * rng.uniform(0.6, 1.0))) ** 2 + ((cols - cx) / radius) ** 2 <= 1
    half = radius * rng.uniform(0.55, 0.75)
    return (np.abs(rows - cy) <= half) & (np.abs(cols - cx) <= radius * 0.8)


def _frame(fitter, mask: np.ndarray, rng: np.random.Generator, offset: float = 0.0) -> np.ndarray:
    truth = rng.normal(0, 0.05, fitter.n_modes)
    surface = fitter.surface(truth)
    frame = np.where(mask, surface, np.nan) + offset + rng.normal(0, 0.01, mask.shape)
    return np.where(np.isnan(surface), np.nan, frame)


def _pair(mask, **settings):
    """The same fitter built twice: moments (checked to be chosen) and operator."""
    moments = build_fitter(mask, dtype=np.float64, refit="moments", **settings)
    operator = build_fitter(mask, dtype=np.float64, refit="operator", **settings)
    assert moments.refit == "moments" and operator.refit == "operator"
    return moments, operator


@pytest.mark.slow
@fuzz_settings(12)
@given(
    kind=st.sampled_from(["disk", "annulus", "ellipse", "rectangle"]),
    size=st.integers(56, 100),
    ordering=st.sampled_from(["noll", "ansi", "fringe"]),
    modes=st.integers(1, 231),
    method=st.sampled_from(["circle", "qr"]),
    remove=st.sampled_from([None, "ptt", "pttp"]),
    pupil_scale=st.sampled_from([None, 1.0, 1.3]),
    seed=st.integers(0, 2**16),
)
def test_moments_equal_the_operator_to_1e_9(kind, size, ordering, modes, method, remove, pupil_scale, seed) -> None:
    assume(max(n for n, _ in mode_list(ordering, modes)) <= 20)  # the range: up to n = 20
    rng = np.random.default_rng(seed)
    mask = _mask(kind, size, rng)
    pupil = None
    if pupil_scale is not None:
        pupil = ((size - 1) / 2 + 0.7, (size - 1) / 2 - 0.4, pupil_scale * size * 0.5)
    settings = dict(method=method, modes=modes, ordering=ordering, pupil=pupil, remove=remove, dtype=np.float64)
    moments_match_or_refuse(mask, settings, lambda operator: _frame(operator, mask, rng, offset=rng.uniform(-3, 3)))


def test_a_degree_20_disk_matches_the_operator_with_residual_and_surface() -> None:
    rng = np.random.default_rng(4)
    mask = _mask("disk", 96, rng)
    moments, operator = _pair(mask, modes=231, remove="pttp")
    assert moments.diagnostics.moment_amplification <= 3e4 and moments.diagnostics.moment_strips > 1
    frame = _frame(operator, mask, rng, offset=40.0)  # a large piston: the shift keeps the sums exact
    a, b = moments.fit(frame, residual=True), operator.fit(frame, residual=True)
    assert_same_fit(a, b, frame)
    scale = np.nanmax(np.abs(frame))
    np.testing.assert_allclose(a.residual_map, b.residual_map, atol=1e-9 * scale, equal_nan=True)
    assert a.residual_pv == pytest.approx(b.residual_pv, rel=1e-6)
    coefficients = rng.normal(0, 0.1, 231)
    np.testing.assert_allclose(moments.surface(coefficients), operator.surface(coefficients), atol=1e-9,
                               equal_nan=True)


@pytest.mark.parametrize("dropped", [7, 3000])  # a few rows, and enough to downdate from mask moments
def test_nan_samples_are_left_out_as_the_operator_leaves_them(dropped) -> None:
    rng = np.random.default_rng(dropped)
    mask = _mask("annulus", 90, rng)
    moments, operator = _pair(mask, modes=66, remove="ptt")
    frame = _frame(operator, mask, rng)
    inside = np.flatnonzero(mask)
    frame.reshape(-1)[rng.choice(inside, dropped, replace=False)] = np.where(rng.random(dropped) < 0.5,
                                                                              np.nan, np.inf)
    a, b = moments.fit(frame, nan_policy="omit", residual=True), operator.fit(frame, nan_policy="omit", residual=True)
    assert a.nan_count == dropped
    assert_same_fit(a, b, frame)
    assert np.array_equal(np.isnan(a.residual_map), np.isnan(b.residual_map))
    with pytest.raises(Exception, match="NaN or infinite"):
        moments.fit(frame)


@pytest.mark.parametrize("refit", ["moments", "operator"])
def test_fit_many_equals_fit_on_each_frame(refit) -> None:
    rng = np.random.default_rng(9)
    mask = _mask("disk", 64, rng)
    fitter = build_fitter(mask, modes=45, remove="ptt", dtype=np.float64, refit=refit)
    frames = np.stack([_frame(fitter, mask, rng, offset=k) for k in range(5)])
    frames[3].reshape(-1)[np.flatnonzero(mask)[:4]] = np.nan  # fitted on its own under the NaN policy
    batch = fitter.fit_many(frames, nan_policy="omit", residual=True)
    assert len(batch) == 5
    for frame, result in zip(frames, batch):
        single = fitter.fit(frame, nan_policy="omit", residual=True)
        np.testing.assert_allclose(result.coefficients, single.coefficients, rtol=1e-12, atol=1e-14)
        assert result.residual_rms == pytest.approx(single.residual_rms, rel=1e-9)
        assert result.nan_count == single.nan_count and result.residual_pv == pytest.approx(single.residual_pv)
    with pytest.raises(Exception, match="NaN or infinite"):
        fitter.fit_many(frames)


def test_float32_frames_are_summed_in_float64() -> None:
    rng = np.random.default_rng(2)
    mask = _mask("disk", 80, rng)
    moments, operator = _pair(mask, modes=231)
    frame = _frame(operator, mask, rng).astype(np.float32)
    # The moments read the float32 samples exactly and sum in float64: the float64 operator on the
    # same (float32-valued) samples is the reference, to the same 1e-9.
    assert_same_fit(moments.fit(frame), operator.fit(frame.astype(np.float64)), frame.astype(np.float64))


def test_a_stored_moment_fitter_round_trips(tmp_path) -> None:
    rng = np.random.default_rng(5)
    mask = _mask("annulus", 70, rng)
    fitter = build_fitter(mask, modes=36, remove="pttp", method="qr")
    assert fitter.refit == "moments"
    save_fitter(fitter, tmp_path / "f.npz")
    loaded = load_fitter(tmp_path / "f.npz")
    frame = _frame(fitter, mask, rng)
    a, b = fitter.fit(frame, residual=True), loaded.fit(frame, residual=True)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    assert loaded.refit == "moments" and loaded.dtype == fitter.dtype and a.residual_rms == b.residual_rms
    with pytest.raises(AttributeError, match="keeps no operator"):
        loaded.operator


def test_concentric_annular_zernike_columns_are_served_by_the_moment_algebra() -> None:
    # No build_fitter method fits annular terms in pixel coordinates today (the mapped methods use
    # them on the map's image); the moment algebra serves them as it serves the circle terms.
    from functools import partial

    from wavestack.pipeline import annular_zernike_basis
    from wavestack.pipeline.fit.legendre_moments import (
        column_coefficients, gram_of, legendre_table, strip_moments, strips_of, triangle_index)

    size, radius, eps = 90, 42.0, 0.4
    rows, cols = np.indices((size, size), dtype=float)
    r = np.hypot(rows - 44.5, cols - 44.5)
    mask = (r <= radius) & (r >= eps * radius)
    modes = mode_list("noll", 66)  # up to n = 10
    columns = partial(annular_zernike_basis, modes, obscuration=eps)
    to_unit = lambda rr, cc: ((cc - 44.5) / radius, (44.5 - rr) / radius)  # noqa: E731
    strips = strips_of(mask, 4)
    coefficients = column_coefficients(lambda x, y: columns(x, y), strips, to_unit, 10)
    pr, pc = np.nonzero(mask)
    explicit = columns(*to_unit(pr.astype(float), pc.astype(float)))
    values = np.empty_like(explicit)
    for strip, t in zip(strips, coefficients):
        inside = (pr >= strip.row0) & (pr < strip.row1)
        p_rows = legendre_table(strip.row0, strip.row1, 10)[pr[inside] - strip.row0]
        p_cols = legendre_table(strip.col0, strip.col1, 10)[pc[inside] - strip.col0]
        products = (p_rows[:, :, None] * p_cols[:, None, :]).reshape(p_rows.shape[0], -1)[:, triangle_index(10)]
        values[inside] = products @ t.T
    # Exact polynomial identity up to rounding (values are O(1), coefficient sums O(1e2)).
    np.testing.assert_allclose(values, explicit, atol=1e-11)
    gram, sums = gram_of(coefficients, strip_moments(mask, strips, 10))
    np.testing.assert_allclose(gram, explicit.T @ explicit, atol=1e-9 * mask.sum())
    np.testing.assert_allclose(sums, explicit.sum(axis=0), atol=1e-9 * mask.sum())
