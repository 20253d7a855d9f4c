"""The run pass of the moment refit: small apertures up to degree 7, float64 sums, one compiled call."""

from __future__ import annotations

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import assume, given
from hypothesis import strategies as st

from wavestack.pipeline import InvalidFrame, build_fitter
from wavestack.pipeline.fit.legendre_moments import Strip, legendre_table
from wavestack.pipeline.fit.moment_chunks import ChunkedPass
from wavestack.pipeline.fit.run_moments import RUN_PASS_MAX_WIDTH, RunPass

from moment_pairs import _relative

from .test_moments import _frame, _mask


def _pass_of(fitter) -> str:
    # The projection is private to the fitter; the tests need to know which pass ran.
    return fitter._projection.float32_frame_pass


@fuzz_settings(200)
@given(rows=st.integers(1, 60), cols=st.integers(1, 60), density=st.floats(0.05, 1.0), degree=st.integers(0, 7),
       single=st.booleans(), shift=st.floats(-2.0, 2.0), seed=st.integers(0, 2**16))
def test_run_moments_equal_the_float64_chunked_moments(rows, cols, density, degree, single, shift, seed) -> None:
    rng = np.random.default_rng(seed)
    inside = rng.random((rows, cols)) < density  # any shape: holes, several runs per row
    assume(inside.any())
    strip = Strip(2, 2 + rows, 3, 3 + cols)
    frame = np.full((rows + 5, cols + 4), np.nan)  # NaN and inf off the fitted pixels
    frame[2:2 + rows, 3:3 + cols] = np.where(inside, rng.normal(size=inside.shape) + 4.0, np.inf)
    frame = frame.astype(np.float32 if single else np.float64)
    tables = [legendre_table(strip.row0, strip.row1, degree)], [legendre_table(strip.col0, strip.col1, degree)]
    moments, squares = RunPass([strip], [inside], *tables).moments(frame, shift)
    expected, expected_squares = ChunkedPass([strip], [inside], *tables, np.float64).moments(frame, shift)
    assert moments.shape == expected.shape == (1, degree + 1, degree + 1)
    np.testing.assert_allclose(moments, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert squares == pytest.approx(expected_squares, rel=1e-12)


def test_small_low_degree_apertures_take_the_run_pass_and_others_do_not() -> None:
    rng = np.random.default_rng(1)
    small = _mask("disk", 120, rng)
    assert _pass_of(build_fitter(small, modes=36)) == "runs"  # degree 7
    assert _pass_of(build_fitter(small, modes=45)) != "runs"  # degree 8
    wide = _mask("disk", int(RUN_PASS_MAX_WIDTH * 1.3), rng)  # wider than the run pass serves
    assert _pass_of(build_fitter(wide, modes=10)) == "float32"


def test_the_run_pass_refit_equals_the_operator_refit_for_float32_frames() -> None:
    rng = np.random.default_rng(2)
    mask = _mask("annulus", 150, rng)
    fitter = build_fitter(mask, modes=36, remove="ptt")
    operator = build_fitter(mask, modes=36, remove="ptt", dtype=np.float64, refit="operator")
    assert _pass_of(fitter) == "runs"
    frame = _frame(operator, mask, rng, offset=25.0).astype(np.float32)  # a large piston
    a, b = fitter.fit(frame), operator.fit(frame.astype(np.float64))
    assert _relative(a.coefficients, b.coefficients) <= 1e-9  # float64 sums: the float64 bound
    assert a.residual_rms == pytest.approx(b.residual_rms, rel=1e-6)


def test_values_outside_the_aperture_do_not_reach_the_run_sums() -> None:
    rng = np.random.default_rng(3)
    mask = _mask("ellipse", 100, rng)
    fitter = build_fitter(mask, modes=28)
    assert _pass_of(fitter) == "runs"
    clean = np.where(mask, _frame(fitter, mask, rng), 0.0)
    noisy = clean.copy()
    noisy[~mask] = rng.choice(np.array([np.nan, np.inf, -np.inf, 1e300]), int((~mask).sum()))
    a, b = fitter.fit(clean), fitter.fit(noisy)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    assert a.residual_rms == b.residual_rms


def test_non_finite_samples_inside_go_to_the_masked_pass_and_its_nan_policy() -> None:
    rng = np.random.default_rng(4)
    mask = _mask("disk", 90, rng)
    fitter = build_fitter(mask, modes=21)
    operator = build_fitter(mask, modes=21, dtype=np.float64, refit="operator")
    assert _pass_of(fitter) == "runs"
    frame = _frame(operator, mask, rng).astype(np.float32)
    inside = np.flatnonzero(mask)
    frame.reshape(-1)[inside[[7, 300, 1000]]] = [np.nan, -np.inf, np.nan]
    with pytest.raises(InvalidFrame, match="NaN or infinite"):
        fitter.fit(frame)
    a, b = fitter.fit(frame, nan_policy="omit"), operator.fit(frame.astype(np.float64), nan_policy="omit")
    assert a.nan_count == b.nan_count == 3
    assert _relative(a.coefficients, b.coefficients) <= 1e-9


def test_fit_many_on_the_run_pass_equals_fit_on_each() -> None:
    rng = np.random.default_rng(5)
    mask = _mask("rectangle", 80, rng)
    fitter = build_fitter(mask, modes=15, remove="ptt")
    assert _pass_of(fitter) == "runs"
    for dtype in (np.float32, np.float64):
        frames = np.stack([_frame(fitter, mask, rng) for _ in range(3)]).astype(dtype)
        for one, many in zip((fitter.fit(f) for f in frames), fitter.fit_many(frames)):
            np.testing.assert_array_equal(one.coefficients, many.coefficients)
            assert one.residual_rms == many.residual_rms
