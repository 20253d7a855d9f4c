"""The one-call refit: where it serves, it gives what the general moment path gives."""

from __future__ import annotations

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import assume, given
from hypothesis import strategies as st

from wavestack.pipeline import InvalidFrame, build_fitter
from wavestack.pipeline.fit import run_refit
from wavestack.pipeline.fit.legendre_moments import Strip, legendre_table
from wavestack.pipeline.fit.moment_chunks import ChunkedPass
from wavestack.pipeline.fit.run_moments import RUN_PASS_MAX_WIDTH, RunPass

from moment_pairs import _relative

from .test_moments import _frame, _mask


def _two_disks(size: int, rng: np.random.Generator) -> np.ndarray:
    """Two disjoint disks side by side: one strip cut into two boxes (a packed run pass of two)."""
    rows, cols = np.indices((size, 2 * size), dtype=float)
    first = np.hypot(rows - size / 2, cols - size / 2) <= size * rng.uniform(0.3, 0.45)
    second = np.hypot(rows - size / 2 - rng.uniform(-3, 3), cols - 1.5 * size) <= size * rng.uniform(0.2, 0.45)
    return first | second


def _aperture(kind: str, size: int, rng: np.random.Generator) -> tuple[np.ndarray, tuple[float, float, float] | None]:
    if kind == "two disks":
        return _two_disks(size, rng), (size - 0.5, (size - 1) / 2, size * 1.2)
    return _mask(kind, size, rng), None


def _general(fitter, frame):
    """The fitter's general path (projection, then the normal equations), with the residual map."""
    return fitter._finish(frame, fitter._projection.project(frame, "raise"), True)


def _serves(fitter) -> bool:
    # The fitter's parts are private; the tests need to know which path a fit takes.
    return fitter._run_refit is not None


@fuzz_settings(40)
@given(kind=st.sampled_from(["disk", "annulus", "ellipse", "rectangle", "two disks"]), size=st.integers(40, 120),
       modes=st.integers(1, 36), ordering=st.sampled_from(["noll", "ansi", "fringe"]),
       method=st.sampled_from(["circle", "qr"]), normalisation=st.sampled_from(["rms", "edge"]),
       single=st.booleans(), offset=st.sampled_from([0.0, 3.0, -40.0]), seed=st.integers(0, 2**16))
def test_the_one_call_refit_equals_the_general_path(kind, size, modes, ordering, method, normalisation, single,
                                                    offset, seed) -> None:
    rng = np.random.default_rng(seed)
    mask, pupil = _aperture(kind, size, rng)
    try:
        fitter = build_fitter(mask, method, modes, ordering, pupil, np.float64, normalisation=normalisation,
                              refit="moments")
    except ValueError:  # moments refused on this aperture (amplification): nothing to compare
        assume(False)
    assume(_serves(fitter))  # Fringe orderings reach degree 8 before 36 terms: beyond the run pass
    frame = _frame(fitter, mask, rng, offset).astype(np.float32 if single else np.float64)
    fast = fitter.fit(frame, residual=True)
    general = _general(fitter, frame)
    assert _relative(fast.coefficients, general.coefficients) <= 1e-12
    if method == "qr":
        assert _relative(fast.circle_coefficients, general.circle_coefficients) <= 1e-12
    else:
        assert fast.circle_coefficients is None
    assert (fast.valid_count, fast.nan_count, fast.removed) == (general.valid_count, 0, None)
    # The residual identity |w - m|^2 - c.b cancels: it holds to rounding of |w - m|^2.
    samples = frame[np.isfinite(general.residual_map)].astype(np.float64)
    spread = float(np.sum((samples - samples.mean()) ** 2))
    identity = fitter.fit(frame)
    assert abs(identity.residual_rms**2 - general.residual_rms**2) * fast.valid_count <= 1e-11 * spread
    # With the map asked for, both paths take the RMS and PV from the same map of the same terms.
    np.testing.assert_allclose(fast.residual_map, general.residual_map, rtol=0, atol=1e-12 * (1 + float(np.nanmax(np.abs(frame)))))
    assert fast.residual_rms == pytest.approx(general.residual_rms, rel=1e-9, abs=1e-15)
    assert fast.residual_pv == pytest.approx(general.residual_pv, rel=1e-9, abs=1e-12)


def test_fit_takes_one_compiled_call_and_returns_what_it_computed(monkeypatch) -> None:
    rng = np.random.default_rng(1)
    mask = _mask("disk", 100, rng)
    fitter = build_fitter(mask, modes=36)
    frame = _frame(fitter, mask, rng, offset=2.0).astype(np.float32)
    calls = []
    real = run_refit._refit

    def counted(*args):
        calls.append(args[0].shape)
        return real(*args)

    monkeypatch.setattr(run_refit, "_refit", counted)
    result = fitter.fit(frame)
    assert calls == [mask.shape]
    fitted = fitter._run_refit.fit(frame)
    np.testing.assert_array_equal(result.coefficients, fitted.mapped[0])
    assert result.residual_rms == pytest.approx(np.sqrt(fitted.residual_sq / result.valid_count), rel=1e-15)
    with_map = fitter.fit(frame, residual=True)  # the residual map: the same one call, then one evaluation
    assert len(calls) == 3
    np.testing.assert_array_equal(with_map.coefficients, result.coefficients)
    np.testing.assert_allclose(with_map.residual_map, fitter._projection.residual(frame, None, fitted.solved)[0])


def test_removal_wide_and_high_degree_fitters_keep_the_general_path() -> None:
    rng = np.random.default_rng(2)
    small = _mask("disk", 90, rng)
    assert _serves(build_fitter(small, modes=36))
    assert not _serves(build_fitter(small, modes=36, remove="ptt"))
    assert not _serves(build_fitter(small, modes=45))  # degree 8: beyond the run pass
    assert not _serves(build_fitter(small, modes=36, refit="operator"))
    wide = _mask("disk", int(RUN_PASS_MAX_WIDTH * 1.2), rng)
    assert not _serves(build_fitter(wide, modes=10))


def test_non_finite_samples_inside_fall_back_to_the_nan_policy() -> None:
    rng = np.random.default_rng(3)
    mask = _mask("annulus", 80, rng)
    fitter = build_fitter(mask, modes=21, dtype=np.float64)
    operator = build_fitter(mask, modes=21, dtype=np.float64, refit="operator")
    frame = _frame(operator, mask, rng)
    inside = np.flatnonzero(mask)
    frame.reshape(-1)[inside[[5, 200]]] = [np.nan, np.inf]
    assert fitter._run_refit.fit(frame) is None
    with pytest.raises(InvalidFrame, match="NaN or infinite"):
        fitter.fit(frame)
    a, b = fitter.fit(frame, nan_policy="omit"), operator.fit(frame, nan_policy="omit")
    assert a.nan_count == b.nan_count == 2
    assert _relative(a.coefficients, b.coefficients) <= 1e-9
    with pytest.raises(InvalidFrame, match="shape"):
        fitter.fit(frame[:-1])


def test_fit_many_equals_fit_on_each_frame() -> None:
    rng = np.random.default_rng(4)
    mask = _two_disks(60, rng)
    fitter = build_fitter(mask, modes=15, pupil=(59.5, 29.5, 70.0))
    assert _serves(fitter)
    frames = np.stack([_frame(fitter, mask, rng) for _ in range(3)]).astype(np.float32)
    frames[1].reshape(-1)[np.flatnonzero(mask)[10]] = np.nan  # this one goes the general way
    for one, many in zip((fitter.fit(f, nan_policy="omit") for f in frames), fitter.fit_many(frames, nan_policy="omit")):
        np.testing.assert_array_equal(one.coefficients, many.coefficients)
        assert (one.residual_rms, one.nan_count) == (many.residual_rms, many.nan_count)
    assert fitter.fit_many(frames, nan_policy="omit")[1].nan_count == 1


@fuzz_settings(100)
@given(heights=st.lists(st.integers(1, 30), min_size=2, max_size=4), degree=st.integers(0, 7),
       single=st.booleans(), seed=st.integers(0, 2**16))
def test_packed_strips_give_each_strips_moments(heights, degree, single, seed) -> None:
    rng = np.random.default_rng(seed)
    strips, inside, row0 = [], [], 0
    for height in heights:  # strips of different heights and widths, one under the other
        width = int(rng.integers(1, 40))
        col0 = int(rng.integers(0, 10))
        strips.append(Strip(row0, row0 + height, col0, col0 + width))
        inside.append(rng.random((height, width)) < 0.7)
        row0 += height
    frame = rng.normal(size=(row0, 50)) + 2.0
    frame = frame.astype(np.float32 if single else np.float64)
    rows = [legendre_table(s.row0, s.row1, degree) for s in strips]
    cols = [legendre_table(s.col0, s.col1, degree) for s in strips]
    moments, squares = RunPass(strips, inside, rows, cols).moments(frame, 0.5)
    expected, expected_squares = ChunkedPass(strips, inside, rows, cols, np.float64).moments(frame, 0.5)
    np.testing.assert_allclose(moments, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert squares == pytest.approx(expected_squares, rel=1e-12)
