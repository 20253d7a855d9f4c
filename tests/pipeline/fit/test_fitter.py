"""The precomputed fitter against an independent least-squares solve of the same problem."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import (
    Aperture,
    IllConditionedBasis,
    InvalidFrame,
    Pupil,
    build_fitter,
    mode_list,
    normalisation_factor,
    remove_physical_terms,
    zernike_basis,
)


def disk_mask(shape: tuple[int, int] = (121, 121), radius: float = 55.0) -> np.ndarray:
    rows, cols = np.indices(shape)
    return np.hypot(rows - (shape[0] - 1) / 2, cols - (shape[1] - 1) / 2) <= radius


def rounded_rectangle(shape=(90, 260), half=(120.0, 34.0), corner=12.0) -> np.ndarray:
    rows, cols = np.indices(shape, dtype=float)
    x = np.abs(cols - (shape[1] - 1) / 2) - (half[0] - corner)
    y = np.abs(rows - (shape[0] - 1) / 2) - (half[1] - corner)
    return np.hypot(np.maximum(x, 0), np.maximum(y, 0)) <= corner


def design_matrix(mask: np.ndarray, pupil: Pupil, modes, normalisation="rms"):
    """The circle basis on the valid pixels, built here from the project conventions."""
    rows, cols = np.nonzero(mask)
    x = (cols - pupil.cx) / pupil.radius
    y = (pupil.cy - rows) / pupil.radius  # y up: row 0 is the top
    return zernike_basis(modes, x, y, normalisation=normalisation), rows, cols


def frame_from(mask, values, rows, cols, fill=np.nan) -> np.ndarray:
    frame = np.full(mask.shape, fill)
    frame[rows, cols] = values
    return frame


@pytest.fixture(scope="module")
def rectangle_case():
    mask = rounded_rectangle()
    fitter = build_fitter(mask, method="circle", modes=36, dtype=np.float64)
    modes = mode_list("noll", 36)
    design, rows, cols = design_matrix(mask, fitter.basis.pupil, modes)
    return mask, fitter, design, rows, cols


def test_circle_fit_recovers_known_coefficients_on_a_thin_aperture(rectangle_case) -> None:
    mask, fitter, design, rows, cols = rectangle_case
    truth = np.random.default_rng(1).normal(0, 0.02, 36)
    result = fitter.fit(frame_from(mask, design @ truth, rows, cols))
    # The circle basis on a 3.5:1 strip is nearly degenerate: kappa(G) ~ 3e10 (kappa(H) ~ 2e5).
    assert fitter.diagnostics.gram_condition > 1e9
    # Exact data in the span: the error is rounding (1e-16) amplified by kappa(H) ~ 2e5 through
    # the orthonormal route, ~1e-12 of 0.02-wave terms. A Cholesky solve of H^T H would amplify
    # by kappa(G) and miss 1e-9 (measured 3.6e-8).
    np.testing.assert_allclose(result.coefficients, truth, atol=1e-9)
    # The residual comes from |w|^2 - c.b, which cannot resolve below about
    # sqrt(eps * sqrt(N)) * RMS(w) = sqrt(2.2e-16 * 127) * 0.03 ~ 5e-9 waves.
    assert result.residual_rms < 2e-8
    assert result.valid_count == mask.sum() and result.nan_count == 0


def test_fit_and_residual_match_lstsq_on_noisy_data(rectangle_case) -> None:
    mask, fitter, design, rows, cols = rectangle_case
    rng = np.random.default_rng(2)
    data = design @ rng.normal(0, 0.02, 36) + rng.normal(0, 0.003, rows.size) + 7.5
    expected, *_ = np.linalg.lstsq(design, data, rcond=None)
    expected_rms = np.sqrt(np.mean((data - design @ expected) ** 2))
    result = fitter.fit(frame_from(mask, data, rows, cols), residual=True)
    # Both solvers carry rounding amplified by kappa(H) ~ 2e5 on data of size ~7.5 (the piston):
    # eps * kappa(H) * |w| ~ 2.2e-16 * 2e5 * 7.5 ~ 3e-10 each, whatever BLAS kernel runs. Measured
    # differences reach 1.5e-10 with OpenBLAS's Haswell kernels; 1e-9 is three times that bound.
    np.testing.assert_allclose(result.coefficients, expected, rtol=0, atol=1e-9)
    assert result.residual_rms == pytest.approx(expected_rms, rel=1e-9)
    residual = result.residual_map[rows, cols]
    np.testing.assert_allclose(residual, data - design @ expected, atol=1e-10)
    assert result.residual_pv == pytest.approx(np.ptp(data - design @ expected), rel=1e-9)
    assert np.isnan(result.residual_map[~mask]).all()


@pytest.mark.parametrize("refit", ["operator", "auto"])  # auto: moments on the disk, operator on the strip
@pytest.mark.parametrize("shape, method", [("disk", "circle"), ("strip", "qr"), ("strip", "circle")])
def test_float32_fitter_agrees_with_float64_within_single_precision(shape, method, refit) -> None:
    mask = disk_mask() if shape == "disk" else rounded_rectangle()
    fitter64 = build_fitter(mask, method=method, modes=36, dtype=np.float64, refit=refit)
    fitter32 = build_fitter(mask, method=method, modes=36, dtype=np.float32, refit=refit)
    design, rows, cols = design_matrix(mask, fitter64.basis.pupil, mode_list("noll", 36))
    rng = np.random.default_rng(3)
    # A large piston (100 waves) on a 0.05-wave signal: the centring step must keep float32 sums
    # from losing the signal.
    data = design @ rng.normal(0, 0.01, 36) + rng.normal(0, 0.002, rows.size) + 100.0
    frame = frame_from(mask, data, rows, cols)
    r64, r32 = fitter64.fit(frame), fitter32.fit(frame)
    # float32 rounds each centred sample and each product term at eps32 = 6e-8 relative; the
    # orthonormal coefficients carry that at the 1e-8-wave level (measured 4e-8 to 6e-8), and the
    # map to the method's own coefficients amplifies it by up to kappa(H) = sqrt(kappa(G)).
    kappa_h = np.sqrt(fitter64.diagnostics.gram_condition)
    bound = 1e-6 * kappa_h  # 1e-6 waves for an orthonormal basis: 20x the measured error
    np.testing.assert_allclose(r32.coefficients[1:], r64.coefficients[1:], atol=bound)
    assert r32.coefficients[0] == pytest.approx(r64.coefficients[0], abs=bound)
    # The residual RMS from the normal-equation identity stays within 0.1 % of float64's
    # (measured 2e-5 on the disk, 2e-4 on the strip).
    assert r32.residual_rms == pytest.approx(r64.residual_rms, rel=1e-3)
    expected = "moments" if refit == "auto" and shape == "disk" else "operator"
    assert fitter32.dtype == np.float32 and fitter32.refit == fitter64.refit == expected
    # The operator is stored in the fit dtype; the moment tables are float64 whatever it is.
    assert fitter32.operator_nbytes * (2 if expected == "operator" else 1) == fitter64.operator_nbytes


def test_integer_frames_are_accepted(rectangle_case) -> None:
    mask, fitter, design, rows, cols = rectangle_case
    frame = frame_from(mask, 0, rows, cols, fill=0).astype(np.uint16)
    frame[rows, cols] = 1000 + np.arange(rows.size) % 7
    expected, *_ = np.linalg.lstsq(design, frame[rows, cols].astype(float), rcond=None)
    np.testing.assert_allclose(fitter.fit(frame).coefficients, expected, atol=1e-9)


def test_qr_is_orthonormal_and_converts_back_to_the_circle_fit(rectangle_case) -> None:
    mask, circle, design, rows, cols = rectangle_case
    qr = build_fitter(mask, method="qr", modes=36, dtype=np.float64)
    assert qr.diagnostics.gram_condition == pytest.approx(1.0, abs=1e-9)
    assert qr.diagnostics.noise_gain == pytest.approx(1.0, abs=1e-9)
    assert qr.basis.normalisation == "aperture-rms"
    data = design @ np.random.default_rng(4).normal(0, 0.02, 36)
    frame = frame_from(mask, data, rows, cols)
    q_result, c_result = qr.fit(frame), circle.fit(frame)
    # Same least-squares problem in another basis of the same span: same circle coefficients.
    np.testing.assert_allclose(q_result.circle_coefficients, c_result.coefficients, atol=1e-9)
    # Orthonormal (unit RMS) columns: the sum of squared coefficients is the mean square signal.
    assert np.sum(q_result.coefficients**2) == pytest.approx(np.mean(data**2), rel=1e-9)
    np.testing.assert_allclose(qr.surface(q_result.coefficients)[rows, cols], data, atol=1e-9)


def test_fringe_edge_normalisation_reads_edge_values() -> None:
    mask = disk_mask()
    fitter = build_fitter(mask, method="circle", modes=16, ordering="fringe", dtype=np.float64)
    assert fitter.basis.normalisation == "edge"
    modes = mode_list("fringe", 16)
    design, rows, cols = design_matrix(mask, fitter.basis.pupil, modes, normalisation="edge")
    truth = np.linspace(-0.1, 0.1, 16)
    result = fitter.fit(frame_from(mask, design @ truth, rows, cols))
    np.testing.assert_allclose(result.coefficients, truth, atol=1e-10)
    # the same map read in unit-RMS Noll terms: defocus (Fringe 4, edge) -> Noll 4 scaled by 1/sqrt(3)
    noll = build_fitter(mask, modes=36, dtype=np.float64).fit(frame_from(mask, design @ truth, rows, cols))
    assert noll.coefficients[3] == pytest.approx(truth[3] / normalisation_factor(2, 0, "rms"), abs=1e-10)


def test_full_disk_is_nearly_orthonormal_for_the_circle_basis() -> None:
    fitter = build_fitter(disk_mask(radius=55), modes=36, dtype=np.float64)
    # ~9500 pixel samples of the unit disk: the discrete Gram matrix departs from the identity
    # only through pixelation of the edge, a few per cent.
    assert 1.0 <= fitter.diagnostics.gram_condition < 1.3
    assert fitter.diagnostics.topology == "simply-connected"


def test_nan_inside_the_aperture_is_reported_or_omitted(rectangle_case) -> None:
    mask, fitter, design, rows, cols = rectangle_case
    rng = np.random.default_rng(5)
    data = design @ rng.normal(0, 0.02, 36) + rng.normal(0, 0.003, rows.size)
    frame = frame_from(mask, data, rows, cols)
    holes = rng.choice(rows.size, 40, replace=False)
    frame[rows[holes], cols[holes]] = np.nan
    with pytest.raises(InvalidFrame, match="40 of .* samples inside the aperture are NaN"):
        fitter.fit(frame)
    result = fitter.fit(frame, nan_policy="omit", residual=True)
    keep = np.setdiff1d(np.arange(rows.size), holes)
    expected, *_ = np.linalg.lstsq(design[keep], data[keep], rcond=None)
    np.testing.assert_allclose(result.coefficients, expected, atol=1e-10)
    expected_rms = np.sqrt(np.mean((data[keep] - design[keep] @ expected) ** 2))
    assert result.residual_rms == pytest.approx(expected_rms, rel=1e-8)
    assert result.nan_count == 40 and result.valid_count == keep.size
    assert np.isnan(result.residual_map[rows[holes], cols[holes]]).all()


def test_frame_errors_name_the_problem(rectangle_case) -> None:
    mask, fitter, *_ = rectangle_case
    with pytest.raises(InvalidFrame, match=r"expected shape \(90, 260\)"):
        fitter.fit(np.zeros((10, 10)))
    with pytest.raises(InvalidFrame, match="expected finite values"):
        fitter.fit(np.full(mask.shape, np.inf))
    with pytest.raises(InvalidFrame, match="finite samples"):
        fitter.fit(np.full(mask.shape, np.nan), nan_policy="omit")


def test_fit_leaves_the_frame_untouched(rectangle_case) -> None:
    mask, fitter, design, rows, cols = rectangle_case
    frame = frame_from(mask, design[:, 4] + 3.0, rows, cols)
    frame[rows[0], cols[0]] = np.nan
    before = frame.copy()
    fitter.fit(frame, nan_policy="omit")
    np.testing.assert_array_equal(frame, before)


def test_surface_reconstructs_the_map_with_nan_outside(rectangle_case) -> None:
    mask, fitter, design, rows, cols = rectangle_case
    truth = np.random.default_rng(6).normal(0, 0.02, 36)
    surface = fitter.surface(truth)
    np.testing.assert_allclose(surface[rows, cols], design @ truth, atol=1e-12)
    assert np.isnan(surface[~mask]).all()
    with pytest.raises(ValueError, match=r"expected shape \(36,\)"):
        fitter.surface(truth[:10])


@pytest.mark.parametrize("terms", ["ptt", "pttp"])
def test_physical_removal_matches_remove_then_fit(rectangle_case, terms) -> None:
    mask, plain, design, rows, cols = rectangle_case
    pupil = plain.basis.pupil
    rng = np.random.default_rng(7)
    data = design @ rng.normal(0, 0.02, 36) + rng.normal(0, 0.003, rows.size)
    frame = frame_from(mask, data, rows, cols)
    fitter = build_fitter(mask, modes=36, dtype=np.float64, remove=terms)
    result = fitter.fit(frame, residual=True)
    residual_map, removed = remove_physical_terms(
        frame, mask, terms, centre=(pupil.cx, pupil.cy), radius_px=pupil.radius
    )
    expected = plain.fit(residual_map)
    np.testing.assert_allclose(result.coefficients, expected.coefficients, atol=1e-10)
    assert result.residual_rms == pytest.approx(expected.residual_rms, rel=1e-8)
    assert result.removed.tilt_x == pytest.approx(removed.tilt_x, abs=1e-12)
    assert result.removed.piston == pytest.approx(removed.piston, abs=1e-12)
    assert (result.removed.power is None) == (terms == "ptt")


def test_physical_terms_have_physical_orientation() -> None:
    mask = disk_mask()
    rows, cols = np.indices(mask.shape)
    # Height rising towards the top of the image (small row numbers) is a positive y tilt.
    frame = np.where(mask, -0.01 * rows + 0.002 * cols, np.nan)
    _, terms = remove_physical_terms(frame, mask, "ptt", centre=(60, 60), radius_px=50)
    assert terms.tilt_y == pytest.approx(0.5, rel=1e-9)  # 0.01 per pixel over 50 pixels
    assert terms.tilt_x == pytest.approx(0.1, rel=1e-9)


def test_user_pupil_excludes_samples_outside_it() -> None:
    mask = disk_mask(radius=55)
    fitter = build_fitter(mask, modes=15, pupil=(60.0, 60.0, 40.0), dtype=np.float64)
    rows, cols = np.nonzero(mask)
    outside = np.hypot(rows - 60.0, cols - 60.0) > 40.0
    assert fitter.diagnostics.excluded_outside_pupil == outside.sum()
    assert fitter.diagnostics.valid_pixels == (~outside).sum()
    assert fitter.basis.pupil == Pupil(60.0, 60.0, 40.0)


def test_default_pupil_is_the_minimum_enclosing_circle() -> None:
    mask = rounded_rectangle()
    fitter = build_fitter(mask, modes=3, dtype=np.float64)
    rows, cols = np.nonzero(mask)
    pupil = fitter.basis.pupil
    distance = np.hypot(cols - pupil.cx, rows - pupil.cy)
    assert distance.max() <= pupil.radius
    assert distance.max() == pytest.approx(pupil.radius, rel=1e-6)  # touches the outermost pixels


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"method": "svd"}, "method: expected one of"),
        ({"modes": 0}, "modes: expected a positive integer"),
        ({"ordering": "zemax"}, "ordering: expected one of"),
        ({"dtype": np.int32}, "dtype: expected float32 or float64"),
        ({"remove": "tilt"}, "terms: expected 'ptt' or 'pttp'"),
        ({"pupil": (1.0, 2.0)}, r"pupil: expected \(cx, cy, r\)"),
        ({"pupil": (1.0, 2.0, -3.0)}, "radius > 0"),
        ({"normalisation": "peak"}, "normalisation: expected"),
    ],
)
def test_bad_arguments_name_the_argument(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        build_fitter(disk_mask(), **kwargs)


def test_too_many_modes_for_the_aperture_is_a_clear_error() -> None:
    mask = np.zeros((20, 20), bool)
    mask[5:12, 5:12] = True  # 49 samples cannot carry 66 modes
    with pytest.raises(IllConditionedBasis, match="expected fewer modes"):
        build_fitter(mask, modes=66, dtype=np.float64)


def test_fitter_accepts_an_aperture_and_reports_timings() -> None:
    aperture = Aperture.from_mask(disk_mask())
    fitter = build_fitter(aperture, modes=10)
    assert fitter.aperture is aperture
    assert set(fitter.diagnostics.timings) >= {"aperture", "basis", "factorise", "total"}
    assert all(t >= 0 for t in fitter.diagnostics.timings.values())
    assert "method='circle'" in repr(fitter)


def test_power_removal_reads_the_paraboloid_height_at_the_radius() -> None:
    mask = rounded_rectangle()
    rows, cols = np.indices(mask.shape)
    cx, cy, radius = 129.5, 44.5, 100.0
    # A paraboloid of revolution reaching 0.3 waves at 100 px, on a tilted plane with a piston.
    height = 0.3 * ((cols - cx) ** 2 + (rows - cy) ** 2) / radius**2 + 0.001 * cols + 2.0
    frame = np.where(mask, height, np.nan)
    fitter = build_fitter(mask, modes=10, pupil=(cx, cy, radius * 1.5), dtype=np.float64, remove="pttp")
    removed = fitter.fit(frame).removed
    # The fitter normalises by its pupil radius (150 px): the same paraboloid is 0.3 * 1.5^2 there.
    assert removed.power == pytest.approx(0.3 * 1.5**2, rel=1e-9)
    assert removed.tilt_x == pytest.approx(0.001 * 150, rel=1e-9)
    _, direct = remove_physical_terms(frame, mask, "pttp", centre=(cx, cy), radius_px=radius)
    assert direct.power == pytest.approx(0.3, rel=1e-9) and direct.tilt_y == pytest.approx(0, abs=1e-12)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_many_modes_use_the_mode_major_operator_and_still_match_lstsq(dtype) -> None:
    mask = disk_mask(radius=55)
    fitter = build_fitter(mask, modes=66, dtype=dtype, remove="ptt", refit="operator")  # 69 columns: mode-major
    assert fitter.operator.flags.f_contiguous and not fitter.operator.flags.c_contiguous
    design, rows, cols = design_matrix(mask, fitter.basis.pupil, mode_list("noll", 66))
    rng = np.random.default_rng(8)
    data = design @ rng.normal(0, 0.02, 66) + rng.normal(0, 0.002, rows.size)
    # remove="ptt" takes a plane out first; it lies in the span of Z1..Z3, so the higher
    # coefficients equal the plain least-squares fit.
    expected, *_ = np.linalg.lstsq(design, data, rcond=None)
    result = fitter.fit(frame_from(mask, data, rows, cols))
    # float32: eps32 * sqrt(N) ~ 6e-6 relative on ~0.05-wave products, kappa(H) ~ 1.1 on a disk
    tolerance = 1e-10 if dtype == np.float64 else 2e-6
    np.testing.assert_allclose(result.coefficients[3:], expected[3:], atol=tolerance)
    # Piston and tilt hold what the Zernike fit sees beyond the removed plane d0 + d1 x + d2 y,
    # which is Z1 = 1, Z2 = 2x, Z3 = 2y in unit-RMS terms.
    removed = result.removed
    plane = np.array([removed.piston, removed.tilt_x / 2, removed.tilt_y / 2])
    np.testing.assert_allclose(result.coefficients[:3], expected[:3] - plane, atol=tolerance)


@pytest.mark.parametrize("method", ["qr", "circle", "csf-qcm"])
@pytest.mark.parametrize("remove", [None, "ptt"])
def test_surface_rms_equals_the_rms_of_the_reconstructed_surface(method: str, remove: str | None) -> None:
    rows, cols = np.indices((120, 160))
    mask = (np.hypot(cols - 80, rows - 60) < 55) & (np.hypot(cols - 90, rows - 57) > 15)
    fitter = build_fitter(mask, method=method, modes=15, remove=remove, dtype=np.float64)
    coefficients = np.random.default_rng(7).normal(size=15)
    surface = fitter.surface(coefficients)
    # the orthonormal shortcut against a pass over every sample: equal to rounding
    assert fitter.surface_rms(coefficients) == pytest.approx(np.sqrt(np.nanmean(surface ** 2)), rel=1e-10)
