"""The chunked passes of the moment refit: float32 frames in float32 products, float64 accumulation.

Small apertures at degree <= 7 take the run pass (:mod:`~wavestack.pipeline.fit.run_moments`);
these tests build their fitters with it switched off (:func:`_chunked_only`), so that the chunked
passes are what they test.
"""

from __future__ import annotations

from contextlib import contextmanager
from unittest import mock

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import assume, given
from hypothesis import strategies as st

from wavestack.pipeline import IllConditionedBasis, InvalidFrame, build_fitter, mode_list
from wavestack.pipeline.fit.legendre_moments import Strip
from wavestack.pipeline.fit.moment_chunks import FLOAT32_MAX_DEGREE, FLOAT32_TOLERANCE, plan_chunks
from wavestack.pipeline.fit import run_moments
from wavestack.pipeline.fit.run_fill import fill_runs

from moment_pairs import _relative, _terms

from .test_moments import _frame, _mask


def _error(a: np.ndarray, b: np.ndarray, scale: float) -> float:
    """Norm-wise error relative to ``b``, or to ``scale`` where ``b`` is smaller (terms near zero)."""
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), scale))


def _uses_float32(fitter) -> bool:
    # The projection is private to the fitter; the tests need to know which pass ran.
    return fitter._projection.float32_frame_pass == "float32"


@contextmanager
def _chunked_only():
    """Fitters built inside take the chunked passes whatever their width (no run pass)."""
    with mock.patch.object(run_moments, "RUN_PASS_MAX_WIDTH", 0):
        yield


def _build(mask, **settings):
    with _chunked_only():
        return build_fitter(mask, **settings)


def _assert_within_float32(a, b, frame: np.ndarray, gain: float) -> None:
    # The pass bounds the error of the orthonormal coefficients; a basis' own coefficients add its
    # noise gain, as they do to the frame's own rounding.
    # Terms that are zero in the truth are compared to the spread of the frame (its units).
    tolerance = FLOAT32_TOLERANCE * max(1.0, gain)
    samples = frame[np.isfinite(frame)].astype(np.float64)
    scale = float(samples.std())
    assert _error(a.coefficients, b.coefficients, scale) <= tolerance
    if b.circle_coefficients is not None:
        assert _error(a.circle_coefficients, b.circle_coefficients, scale) <= tolerance
    if b.removed is not None:
        assert _error(_terms(a.removed), _terms(b.removed), scale) <= tolerance
    energy = float(np.mean(samples**2))
    assert abs(a.residual_rms**2 - b.residual_rms**2) <= 1e-6 * energy
    assert a.valid_count == b.valid_count and a.nan_count == b.nan_count


@fuzz_settings(12)
@given(
    kind=st.sampled_from(["disk", "annulus", "ellipse", "rectangle"]),
    size=st.integers(56, 160),
    ordering=st.sampled_from(["noll", "ansi", "fringe"]),
    modes=st.integers(1, 36),
    method=st.sampled_from(["circle", "qr"]),
    remove=st.sampled_from([None, "ptt", "pttp"]),
    seed=st.integers(0, 2**16),
)
def test_float32_frames_match_the_float64_operator_within_the_float32_tolerance(
        kind, size, ordering, modes, method, remove, seed) -> None:
    assume(max(n for n, _ in mode_list(ordering, modes)) <= FLOAT32_MAX_DEGREE)
    rng = np.random.default_rng(seed)
    mask = _mask(kind, size, rng)
    settings = dict(method=method, modes=modes, ordering=ordering, remove=remove)
    try:
        operator = build_fitter(mask, refit="operator", dtype=np.float64, **settings)
    except IllConditionedBasis:
        assume(False)
    fitter = _build(mask, dtype=np.float32, **settings)
    assume(fitter.refit == "moments" and _uses_float32(fitter))
    frame = _frame(operator, mask, rng, offset=rng.uniform(-3, 3)).astype(np.float32)
    _assert_within_float32(fitter.fit(frame), operator.fit(frame.astype(np.float64)), frame,
                           fitter.diagnostics.noise_gain)


def test_a_36_mode_disk_uses_the_float32_pass_and_a_degree_8_one_does_not() -> None:
    rng = np.random.default_rng(1)
    mask = _mask("disk", 120, rng)
    low, high = _build(mask, modes=36), _build(mask, modes=45)  # degree 7, degree 8
    assert low.refit == high.refit == "moments"
    assert _uses_float32(low) and not _uses_float32(high)
    operator = build_fitter(mask, modes=36, dtype=np.float64, refit="operator")
    frame = _frame(operator, mask, rng, offset=25.0).astype(np.float32)  # a large piston
    _assert_within_float32(low.fit(frame), operator.fit(frame.astype(np.float64)), frame, 1.0)


def test_values_outside_the_aperture_do_not_reach_the_float32_sums() -> None:
    rng = np.random.default_rng(3)
    mask = _mask("annulus", 100, rng)
    fitter = _build(mask, modes=28, remove="ptt")
    assert _uses_float32(fitter)
    frame = _frame(fitter, mask, rng).astype(np.float32)
    clean = np.where(mask, frame, np.float32(0.0))
    noisy = clean.copy()
    outside = np.flatnonzero(~mask)
    noisy.reshape(-1)[outside] = rng.choice(np.array([np.nan, np.inf, -np.inf, 3e38], dtype=np.float32),
                                            outside.size)
    a, b = fitter.fit(clean), fitter.fit(noisy)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    assert a.residual_rms == b.residual_rms


def test_non_finite_samples_inside_go_to_the_float64_pass_and_its_nan_policy() -> None:
    rng = np.random.default_rng(6)
    mask = _mask("disk", 90, rng)
    fitter = _build(mask, modes=21)
    operator = build_fitter(mask, modes=21, dtype=np.float64, refit="operator")
    frame = _frame(operator, mask, rng).astype(np.float32)
    inside = np.flatnonzero(mask)
    frame.reshape(-1)[inside[[5, 400, 900]]] = [np.nan, np.inf, np.nan]
    with pytest.raises(InvalidFrame, match="NaN or infinite"):
        fitter.fit(frame)
    a, b = fitter.fit(frame, nan_policy="omit"), operator.fit(frame.astype(np.float64), nan_policy="omit")
    assert a.nan_count == 3
    assert _relative(a.coefficients, b.coefficients) <= 1e-9  # the float64 pass: the float64 bound


def test_float32_overflow_goes_to_the_float64_pass() -> None:
    rng = np.random.default_rng(8)
    mask = _mask("disk", 70, rng)
    fitter = _build(mask, modes=10)
    operator = build_fitter(mask, modes=10, dtype=np.float64, refit="operator")
    # Samples up to float32's largest (3.4e38): their row sums overflow float32 (the squares,
    # summed in float64, would not).
    frame = _frame(operator, mask, rng)
    frame = (frame * (3e38 / np.nanmax(np.abs(frame)))).astype(np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        moments, _ = fitter._projection._single.moments(frame, float(np.mean(frame[mask], dtype=np.float64)))
    assert not np.isfinite(moments).all()
    a, b = fitter.fit(frame), operator.fit(frame.astype(np.float64))
    assert np.isfinite(a.residual_rms)
    assert _relative(a.coefficients, b.coefficients) <= 1e-9


@fuzz_settings(200)
@given(rows=st.integers(1, 40), cols=st.integers(1, 40), density=st.floats(0.05, 1.0),
       chunk_bytes=st.integers(4, 2048), seed=st.integers(0, 2**16), single=st.booleans())
def test_chunks_copy_each_fitted_pixel_once_and_zero_the_rest(rows, cols, density, chunk_bytes, seed,
                                                               single) -> None:
    rng = np.random.default_rng(seed)
    inside = rng.random((rows, cols)) < density
    assume(inside.any())
    dtype = np.float32 if single else np.float64
    frame = np.full((rows + 7, cols + 9), np.nan, dtype=dtype)  # NaN, inf off the fitted pixels
    frame[3:3 + rows, 5:5 + cols] = np.where(inside, rng.normal(size=inside.shape), np.inf)
    strip = Strip(3, 3 + rows, 5, 5 + cols)
    copied = np.zeros((rows, cols))
    count = np.zeros((rows, cols), dtype=int)
    squares = 0.0
    for chunk in plan_chunks(inside, strip, chunk_bytes, np.dtype(dtype).itemsize):
        block = np.full((chunk.row1 - chunk.row0, chunk.col1 - chunk.col0), 7.0, dtype=dtype)
        squares += fill_runs(frame, dtype(0.25), chunk.row0, chunk.col0, chunk.runs, block)
        here = (slice(chunk.row0 - 3, chunk.row1 - 3), slice(chunk.col0 - 5, chunk.col1 - 5))
        copied[here] += block
        count[here] += 1
    expected = np.where(inside, frame[3:3 + rows, 5:5 + cols] - dtype(0.25), 0.0)
    np.testing.assert_array_equal(copied, expected)
    assert count[inside].max() == 1
    assert squares == pytest.approx(float(np.sum(expected.astype(np.float64) ** 2)), rel=1e-12)


def test_threads_sharing_a_fitter_do_not_share_its_buffers() -> None:
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(11)
    mask = _mask("disk", 512, rng)  # many chunks: the threads' passes overlap
    fitter = _build(mask, modes=15)
    frames = [_frame(fitter, mask, rng).astype(np.float32) for _ in range(4)]
    alone = [fitter.fit(frame).coefficients for frame in frames]
    with ThreadPoolExecutor(max_workers=4) as pool:
        for _ in range(10):
            together = list(pool.map(lambda frame: fitter.fit(frame).coefficients, frames))
            for a, b in zip(alone, together):
                np.testing.assert_array_equal(a, b)


def test_fit_many_of_float32_frames_equals_fit_on_each() -> None:
    rng = np.random.default_rng(12)
    mask = _mask("disk", 64, rng)
    fitter = _build(mask, modes=21, remove="ptt")
    assert _uses_float32(fitter)
    frames = np.stack([_frame(fitter, mask, rng, offset=k) for k in range(4)]).astype(np.float32)
    frames[2].reshape(-1)[np.flatnonzero(mask)[:3]] = np.nan  # fitted on its own under the NaN policy
    batch = fitter.fit_many(frames, nan_policy="omit")
    for frame, result in zip(frames, batch):
        single = fitter.fit(frame, nan_policy="omit")
        np.testing.assert_array_equal(result.coefficients, single.coefficients)
        assert result.residual_rms == single.residual_rms and result.nan_count == single.nan_count
