"""The ``annulus`` fit method: annular Zernike terms over the pupil annulus on the pixel grid."""

from __future__ import annotations

import numpy as np
import pytest
from fuzz import fuzz_settings
from moment_pairs import moments_match_or_refuse
from hypothesis import assume, given
from hypothesis import strategies as st

from wavestack.pipeline import (
    Aperture,
    Pupil,
    annular_zernike_basis,
    annulus_obscuration,
    available_methods,
    build_fitter,
    mode_list,
)
from wavestack.pipeline.fit.moment_build import boxes_of
from wavestack.pipeline.fit.store import load_fitter, save_fitter


def _ring(size: int, centre: tuple[float, float], radius: float, eps: float) -> np.ndarray:
    rows, cols = np.indices((size, size), dtype=float)
    r = np.hypot(rows - centre[1], cols - centre[0])
    return (r <= radius) & (r >= eps * radius)


def test_annulus_is_an_available_method() -> None:
    assert "annulus" in available_methods()


def test_known_annular_coefficients_are_recovered_with_the_measured_obscuration() -> None:
    # A ring of radii 0.35 R .. R drawn from annular Zernike terms of that obscuration: the method
    # measures the hole (to within the pixel grid: a pixel of R = 60 px is 0.017) and recovers
    # the coefficients; on the ring's own ratio the fit is exact to rounding.
    size, centre, radius, eps = 128, (63.3, 64.1), 60.0, 0.35
    mask = _ring(size, centre, radius, eps)
    fitter = build_fitter(mask, method="annulus", modes=45, ordering="ansi", dtype=np.float64)
    pupil = fitter.basis.pupil
    measured = fitter.basis.annular_obscuration
    assert fitter.diagnostics.obscuration_source == "measured" and fitter.refit == "moments"
    assert abs(measured - eps) < 1.0 / radius and abs(pupil.radius - radius) < 1.0
    rows, cols = np.nonzero(mask)
    rho = np.hypot(cols - pupil.cx, rows - pupil.cy) / pupil.radius
    assert rho.min() == pytest.approx(measured, rel=1e-12)  # the inscribed circle touches a pixel centre
    truth = np.random.default_rng(3).normal(0, 0.2, 45)
    x, y = (cols - pupil.cx) / pupil.radius, (pupil.cy - rows) / pupil.radius
    frame = np.full(mask.shape, np.nan)
    frame[rows, cols] = annular_zernike_basis(mode_list("ansi", 45), x, y, measured) @ truth
    result = fitter.fit(frame)
    np.testing.assert_allclose(result.coefficients, truth, atol=1e-10)
    # Without the map the RMS is the identity |w|^2 - c.b, which cancels to ~1e-12 of |w|^2 in
    # float64; the residual map's own sum of squares is exact to rounding.
    assert result.residual_rms < 1e-6 * float(np.sqrt(np.nanmean(frame**2)))
    exact = fitter.fit(frame, residual=True)
    assert exact.residual_rms < 1e-10 and result.basis.annular_obscuration == measured
    assert result.basis.normalisation == "rms" and fitter.diagnostics.noise_gain < 1.1  # near orthonormal


@pytest.mark.parametrize("refit", ["moments", "operator"])
def test_a_given_obscuration_is_used_and_fringe_terms_stay_unit_rms(refit) -> None:
    mask = _ring(96, (47.5, 47.5), 44.0, 0.5)
    fitter = build_fitter(mask, method="annulus", modes=16, ordering="fringe", obscuration=0.45,
                          dtype=np.float64, refit=refit)
    assert fitter.basis.annular_obscuration == 0.45 and fitter.diagnostics.obscuration_source == "given"
    assert fitter.basis.normalisation == "rms" and fitter.refit == refit  # "edge" is a circle notion
    truth = np.linspace(-0.3, 0.3, 16)
    result = fitter.fit(fitter.surface(truth))
    np.testing.assert_allclose(result.coefficients, truth, atol=1e-10)


def test_an_aperture_without_a_central_hole_is_refused_unless_the_obscuration_is_given() -> None:
    disk = _ring(64, (31.5, 31.5), 30.0, 0.0)
    with pytest.raises(ValueError, match=r"no hole around the pupil centre.*--obscuration E"):
        build_fitter(disk, method="annulus")
    fitter = build_fitter(disk, method="annulus", obscuration=0.3, modes=10)  # pixels inside are fitted too
    assert fitter.basis.annular_obscuration == 0.3 and fitter.diagnostics.valid_pixels == disk.sum()
    rows, cols = np.indices((64, 64))
    off_centre = disk & (np.hypot(rows - 31.5, cols - 44) > 6)  # a hole, but not around the centre
    assert len(Aperture.from_mask(off_centre).holes) == 1
    with pytest.raises(ValueError, match="no hole around the pupil centre"):
        build_fitter(off_centre, method="annulus")


@pytest.mark.parametrize("value", [0.0, 1.0, -0.2, 1.5, float("nan"), True, "0.3"])
def test_an_obscuration_outside_zero_to_one_is_refused(value) -> None:
    with pytest.raises(ValueError, match="obscuration: expected a number between 0 and 1"):
        build_fitter(_ring(48, (23.5, 23.5), 22.0, 0.4), method="annulus", obscuration=value)


def test_an_obscuration_with_another_method_is_refused() -> None:
    with pytest.raises(ValueError, match="only the 'annulus' method takes an obscuration"):
        build_fitter(_ring(48, (23.5, 23.5), 22.0, 0.4), method="circle", obscuration=0.4)


@fuzz_settings(40)
@given(size=st.integers(24, 90), eps=st.floats(0.1, 0.9), dx=st.floats(-3, 3), dy=st.floats(-3, 3),
       grow=st.floats(1.0, 1.2))
def test_the_measured_obscuration_is_the_nearest_valid_pixel_centre(size, eps, dx, dy, grow) -> None:
    centre = ((size - 1) / 2 + dx, (size - 1) / 2 + dy)
    mask = _ring(size, centre, 0.4 * size, eps)
    aperture = Aperture.from_mask(mask)
    assume(aperture.topology.value == "doubly-connected")
    pupil = Pupil(centre[0], centre[1], 0.4 * size * grow)
    rows, cols = np.nonzero(mask)
    nearest = np.hypot(cols - pupil.cx, rows - pupil.cy).min()  # brute force over every pixel
    found = annulus_obscuration(aperture, pupil)
    assert found.ratio == pytest.approx(nearest / pupil.radius, rel=1e-12) and found.source == "measured"


def test_moment_boxes_are_disjoint_cover_the_mask_and_never_span_the_hole() -> None:
    mask = _ring(120, (60.2, 59.1), 56.0, 0.6)
    boxes = boxes_of(mask, 16)
    cover = np.zeros(mask.shape, dtype=int)
    for b in boxes:
        cover[b.row0:b.row1, b.col0:b.col1] += 1
    assert cover.max() == 1 and np.all(cover[mask] == 1)
    assert not cover[59, 60]  # the hole's centre lies in no box
    disk = _ring(120, (60.2, 59.1), 56.0, 0.0)
    assert len(boxes_of(disk, 16)) == 16  # a mask without column gaps keeps its strips


def test_a_stored_annulus_fitter_keeps_its_obscuration(tmp_path) -> None:
    mask = _ring(80, (39.5, 40.0), 37.0, 0.3)
    fitter = build_fitter(mask, method="annulus", modes=28, remove="ptt")
    save_fitter(fitter, tmp_path / "f.npz")
    loaded = load_fitter(tmp_path / "f.npz")
    assert loaded.basis == fitter.basis and loaded.diagnostics.obscuration_source == "measured"
    frame = fitter.surface(np.linspace(0.1, -0.1, 28))
    np.testing.assert_array_equal(loaded.fit(frame).coefficients, fitter.fit(frame).coefficients)


@pytest.mark.slow
@fuzz_settings(12)
@given(
    size=st.integers(56, 110),
    eps=st.floats(0.1, 0.85),
    given_ratio=st.sampled_from([None, 0.9, 1.0]),
    ordering=st.sampled_from(["noll", "ansi", "fringe"]),
    modes=st.integers(1, 231),
    remove=st.sampled_from([None, "ptt", "pttp"]),
    pupil_scale=st.sampled_from([None, 1.0, 1.2]),
    seed=st.integers(0, 2**16),
)
def test_annulus_moments_equal_the_operator_to_1e_9(size, eps, given_ratio, ordering, modes, remove, pupil_scale,
                                                    seed) -> None:
    assume(max(n for n, _ in mode_list(ordering, modes)) <= 20)  # the range: up to n = 20
    rng = np.random.default_rng(seed)
    centre = tuple((size - 1) / 2 + rng.uniform(-2, 2, 2))
    radius = size * rng.uniform(0.38, 0.48)
    mask = _ring(size, centre, radius, eps)
    assume(Aperture.from_mask(mask).topology.value == "doubly-connected")
    pupil = None if pupil_scale is None else (centre[0] + 0.3, centre[1] - 0.2, pupil_scale * radius)
    obscuration = None if given_ratio is None else eps * given_ratio
    settings = dict(method="annulus", modes=modes, ordering=ordering, pupil=pupil, remove=remove,
                    obscuration=obscuration, dtype=np.float64)

    def frame_of(operator):
        truth = rng.normal(0, 0.05, operator.n_modes)
        return operator.surface(truth) + rng.uniform(-3, 3) + rng.normal(0, 0.01, mask.shape)

    moments_match_or_refuse(mask, settings, frame_of)
