"""Shack-Hartmann chain: synthetic spot frames -> centroids -> slopes -> modal and zonal wavefronts.

The synthetic sensor: a 1280 x 1024 camera (5.5 um pixels) behind a 40 x 40 lenslet array of
pitch 25 px (137.5 um) and focal length 5 mm; the pupil is the circle inscribed in the array
(radius 500 px), lenslets whose centre lies outside it stay dark (the corners). Each lit
lenslet images a pixel-integrated Gaussian spot (sigma 1.5 px, 20000 photo-electrons) displaced
by ``f * <grad W>``, the wavefront gradient averaged over the lenslet square (4 x 4
Gauss-Legendre), on a 100-count offset with shot noise and 3-count read noise.

Error budget behind the tolerances (measured over 10 noise seeds while writing these tests,
default threshold 0.1):

* centroid error 0.014 px rms per axis (photon limit sigma / sqrt(N) = 0.011 px, plus read
  noise in the thresholded pixels and the centroid's pixel-phase bias), i.e. slope noise
  0.014 * 5.5^2 / 5000 = 8.5e-5 um/px; through the modal reconstructor that is <= 6.4e-4 um
  rms per coefficient (tilt, the worst);
* reconstructing with gradients at the lenslet *centres* while the spots follow the
  subaperture-*mean* gradient costs up to 1.3e-3 um for the third- and fourth-order terms
  (noise-free run);
* observed worst coefficient error 2.4e-3 um (mean of the per-frame maxima 1.7e-3 um), hence
  the tolerance 0.01 um (lambda/63 at 633 nm, 0.5 % of the largest coefficient);
* zonal: Southwell's trapezoid rule is exact for quadratic wavefronts; the cubic and quartic
  terms leave 4.3e-3 um rms (1.1e-2 um max) noise-free, noise brings it to at most 5.3e-3 um
  rms and 1.7e-2 um max: tolerance 0.01 um rms and 0.03 um max, against a 2.8 um rms
  wavefront.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import erf

from wavestack.pipeline.zernike.annular import annular_zernike_gradient
from wavestack.pipeline.aperture.region import Aperture
from wavestack.pipeline.mapping.qcm import csf_qcm_map
from wavestack.pipeline.shack_hartmann.centroids import Centroider, SpotMeasurement
from wavestack.pipeline.shack_hartmann.lattice import LensletLattice
from wavestack.pipeline.shack_hartmann.lattice_detection import detect_lattice
from wavestack.pipeline.shack_hartmann.spot_slopes import convert_slopes, slopes
from wavestack.pipeline.shack_hartmann.modal import ModalReconstructor
from wavestack.pipeline.shack_hartmann.zonal import SouthwellReconstructor, southwell_reconstruct
from wavestack.pipeline.zernike.circle import zernike_basis, zernike_gradient
from wavestack.pipeline.zernike.indices import mode_list

FRAME_SHAPE = (1024, 1280)
FOCAL_UM = 5000.0
PIXEL_UM = 5.5
SIGMA_PX = 1.5
FLUX = 20000.0
BIAS = 100.0
READ_NOISE = 3.0
MIN_INTENSITY = 3000.0  # lit lenslets hold >= 12000 thresholded counts, dark ones < 700
SHAPE = (40, 40)  # rows x cols of lenslets


def square_array(pitch: float, corner: tuple[float, float], shape: tuple[int, int] = SHAPE) -> LensletLattice:
    """An axis-aligned square array whose lenslet (0, 0) has its top-left cell corner at ``corner``."""
    return LensletLattice.array("square", pitch, shape, first_centre_px=(corner[0] + pitch / 2, corner[1] + pitch / 2))


def spots_of(frame: np.ndarray, grid: LensletLattice, **options) -> SpotMeasurement:
    """One frame's spots: a centroider built for its shape, then the measurement."""
    return Centroider.build(grid, np.shape(frame), **options).measure(frame)


GRID = square_array(25.0, (139.5, 11.5))
ODD_GRID = square_array(24.6, (150.3, 20.7))
MODES = mode_list("noll", 15)
TRUTH = np.zeros(15)
TRUTH[1:11] = [2.0, -1.5, 1.0, 0.5, -0.4, 0.3, 0.2, 0.15, -0.1, 0.2]  # um, Noll 2..11
MODAL_TOL_UM = 0.01
ZONAL_RMS_TOL_UM = 0.01
ZONAL_MAX_TOL_UM = 0.03


# --------------------------------------------------------------------------- synthetic sensor


def pupil_of(grid: LensletLattice) -> tuple[tuple[float, float], float]:
    """Pupil inscribed in the array: centre (col, row) and radius, pixels."""
    shape = grid.rectangle()
    centres = grid.centres().reshape(*shape, 2)
    return (float(centres[0, :, 0].mean()), float(centres[:, 0, 1].mean())), 0.5 * grid.pitch_px * min(shape)


def mean_gradient(grid: LensletLattice, coefficients: np.ndarray, order: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """dW/dx, dW/dy (um per pixel, y up) averaged over each lenslet square, shape (L,) each."""
    (col0, row0), radius = pupil_of(grid)
    nodes, weights = np.polynomial.legendre.leggauss(order)
    nodes = nodes * grid.pitch_px / 2
    d_col, d_row = np.repeat(nodes, order), np.tile(nodes, order)
    weight = np.outer(weights, weights).ravel() / 4
    centres = grid.centres().reshape(-1, 2)
    u = ((centres[:, 0, None] + d_col) - col0).ravel() / radius
    v = -((centres[:, 1, None] + d_row) - row0).ravel() / radius
    grad_u, grad_v = zernike_gradient(MODES, u, v)
    gx = (grad_u @ coefficients).reshape(-1, order * order) @ weight / radius
    gy = (grad_v @ coefficients).reshape(-1, order * order) @ weight / radius
    return gx, gy


def wavefront_at_centres(grid: LensletLattice, coefficients: np.ndarray) -> np.ndarray:
    """W (um) at the lenslet centres, shape (L,)."""
    (col0, row0), radius = pupil_of(grid)
    centres = grid.centres().reshape(-1, 2)
    return zernike_basis(MODES, (centres[:, 0] - col0) / radius, -(centres[:, 1] - row0) / radius) @ coefficients


def render(grid: LensletLattice, coefficients: np.ndarray, seed: int, patch: int = 13):
    """Spot frame (uint16), true spot positions (L, 2) (col, row) and lit lenslets (L,)."""
    rng = np.random.default_rng(seed)
    (col0, row0), radius = pupil_of(grid)
    centres = grid.centres().reshape(-1, 2)
    lit = np.hypot(centres[:, 0] - col0, centres[:, 1] - row0) <= radius
    gx, gy = mean_gradient(grid, np.asarray(coefficients, dtype=np.float64))
    spots = centres + np.column_stack([gx, -gy]) * FOCAL_UM / PIXEL_UM**2  # displacement = f grad W
    shown = spots[lit]
    start = np.rint(shown).astype(int) - patch // 2
    edges = np.arange(patch + 1) - 0.5

    def profile(position: np.ndarray, first: np.ndarray) -> np.ndarray:
        return 0.5 * np.diff(erf((first[:, None] + edges - position[:, None]) / (SIGMA_PX * np.sqrt(2))), axis=1)

    values = FLUX * profile(shown[:, 1], start[:, 1])[:, :, None] * profile(shown[:, 0], start[:, 0])[:, None, :]
    rows = start[:, 1, None, None] + np.arange(patch)[None, :, None]
    cols = start[:, 0, None, None] + np.arange(patch)[None, None, :]
    flat = (rows * FRAME_SHAPE[1] + cols).ravel()
    expected = np.bincount(flat, weights=values.ravel(), minlength=FRAME_SHAPE[0] * FRAME_SHAPE[1])
    frame = rng.poisson(expected.reshape(FRAME_SHAPE)) + BIAS + rng.normal(0.0, READ_NOISE, FRAME_SHAPE)
    return np.clip(np.rint(frame), 0, 65535).astype(np.uint16), spots, lit


def slopes_per_pixel(measurement: SpotMeasurement, reference) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slopes in um of wavefront per pixel (the reconstructors' unit for pixel centres), valid."""
    result = slopes(measurement, reference, FOCAL_UM, PIXEL_UM)
    sx, sy = convert_slopes(result, wavefront_unit_um=1.0, length_unit_um=PIXEL_UM)
    return sx, sy, result.valid


@pytest.fixture(scope="module")
def reference_frame():
    return render(GRID, np.zeros(15), seed=1)


@pytest.fixture(scope="module")
def aberrated_frame():
    return render(GRID, TRUTH, seed=2)


@pytest.fixture(scope="module")
def aberrated_slopes(aberrated_frame):
    frame, _, _ = aberrated_frame
    measurement = Centroider.build(GRID, FRAME_SHAPE, min_intensity=MIN_INTENSITY).measure(frame)
    return slopes_per_pixel(measurement, GRID.centres())


def circle_reconstructor(valid: np.ndarray) -> ModalReconstructor:
    (col0, row0), radius = pupil_of(GRID)
    return ModalReconstructor.for_circle(GRID.centres_xy(), (col0, -row0), radius, MODES, valid)


# --------------------------------------------------------------------------- grid


def test_grid_centres_windows_and_physical_coordinates() -> None:
    assert GRID.rectangle() == SHAPE and GRID.count == 1600
    centres = GRID.centres().reshape(*SHAPE, 2)
    assert centres[0, 0].tolist() == [152.0, 24.0]
    assert centres[2, 3].tolist() == [152.0 + 75.0, 24.0 + 50.0]
    xy = GRID.centres_xy()
    assert xy[3 + 2 * 40].tolist() == [227.0, -74.0]  # row-major, y = -row
    row_starts, col_starts, width = (starts.reshape(SHAPE) if np.ndim(starts) else starts
                                     for starts in GRID.window_starts())
    assert width == 25 and col_starts[0, 0] == 140 and row_starts[0, 0] == 12
    assert np.all(np.diff(col_starts, axis=1) == 25) and np.all(np.diff(row_starts, axis=0) == 25)
    assert np.all(row_starts == row_starts[:, :1]) and np.all(col_starts == col_starts[:1])  # a block grid
    rows, cols, odd_width = ODD_GRID.window_starts()
    assert odd_width == 24
    # every window lies within its lenslet square, centred to half a pixel
    odd_centres = ODD_GRID.centres()
    assert np.all(np.abs(cols + 11.5 - odd_centres[:, 0]) <= 0.5 + 1e-9)
    assert np.all(np.abs(rows + 11.5 - odd_centres[:, 1]) <= 0.5 + 1e-9)


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(pitch_px=3.0, first_centre_px=(0.0, 0.0), shape=(2, 2)), "pitch_px"),
        (dict(pitch_px=float("nan"), first_centre_px=(0.0, 0.0), shape=(2, 2)), "pitch_px"),
        (dict(pitch_px=10.0, first_centre_px=(0.0, float("inf")), shape=(2, 2)), "first_centre_px"),
        (dict(pitch_px=10.0, first_centre_px=(0.0,), shape=(2, 2)), "first_centre_px"),
        (dict(pitch_px=10.0, first_centre_px=(0.0, 0.0), shape=(0, 2)), "shape"),
        (dict(pitch_px=10.0, first_centre_px=(0.0, 0.0), shape=(2.5, 2)), "shape"),
    ],
)
def test_grid_rejects_bad_fields(kwargs, word) -> None:
    with pytest.raises(ValueError, match=word):
        LensletLattice.array("square", **kwargs)


def _found_centres_match(found: LensletLattice, grid: LensletLattice, lit: np.ndarray, atol: float) -> None:
    """One found lenslet per lit lenslet of ``grid``, each centre within ``atol`` px of the true one."""
    true = grid.centres()[lit]
    mine = found.centres()
    nearest = np.argmin(np.hypot(*(mine[:, None, :] - true[None]).transpose(2, 0, 1)), axis=1)
    assert found.count == lit.sum() and np.unique(nearest).size == found.count
    assert np.abs(mine - true[nearest]).max() < atol


def test_detect_lattice_on_reference_frame(reference_frame) -> None:
    frame, _, lit = reference_frame
    found = detect_lattice(frame)
    assert found.kind == "square"
    assert abs(found.pitch_px - GRID.pitch_px) < 0.1
    _found_centres_match(found, GRID, lit, atol=0.1)
    # the fit to all spots is far better than the requirement
    assert abs(found.pitch_px - GRID.pitch_px) < 1e-3


def test_detect_lattice_non_integer_pitch() -> None:
    frame, _, lit = render(ODD_GRID, np.zeros(15), seed=3)
    found = detect_lattice(frame)
    assert found.kind == "square"
    assert abs(found.pitch_px - ODD_GRID.pitch_px) < 0.1
    _found_centres_match(found, ODD_GRID, lit, atol=0.1)


def test_detect_lattice_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="2-D"):
        detect_lattice(np.zeros(100))
    with pytest.raises(ValueError, match="finite"):
        detect_lattice(np.full((64, 64), np.nan))
    with pytest.raises(ValueError, match="spot"):
        detect_lattice(np.full((64, 64), 7.0))


# --------------------------------------------------------------------------- centroiding


@pytest.mark.parametrize("grid, seed", [(GRID, 4), (ODD_GRID, 5)])
def test_centroids_match_true_spots(grid, seed) -> None:
    frame, spots, lit = render(grid, TRUTH, seed=seed)
    measured = Centroider.build(grid, FRAME_SHAPE, min_intensity=MIN_INTENSITY).measure(frame)
    error = measured.centroids[lit] - spots[lit]
    assert np.all(np.sqrt(np.mean(error**2, axis=0)) < 0.03)  # photon + read noise ~0.017 px
    assert np.abs(error).max() < 0.1
    assert np.all(np.abs(error.mean(axis=0)) < 0.005)  # no systematic offset


def test_dark_lenslets_are_invalid(reference_frame) -> None:
    frame, _, lit = reference_frame
    assert 0 < lit.sum() < lit.size  # the corners are dark
    measured = spots_of(frame, GRID, min_intensity=MIN_INTENSITY)
    assert np.array_equal(measured.valid, lit)
    assert measured.intensity[~lit].max() < 0.1 * measured.intensity[lit].min()
    # an aperture mask (pixels) or a lenslet mask removes lenslets regardless of light
    (col0, row0), radius = pupil_of(GRID)
    rows, cols = np.mgrid[: FRAME_SHAPE[0], : FRAME_SHAPE[1]]
    small = np.hypot(cols - col0, rows - row0) <= 0.5 * radius
    masked = spots_of(frame, GRID, min_intensity=MIN_INTENSITY, mask=small)
    centres = GRID.centres()
    inside = np.hypot(*(np.rint(centres) - [col0, row0]).T) <= 0.5 * radius
    assert np.array_equal(masked.valid, lit & inside)
    by_lenslet = spots_of(frame, GRID, min_intensity=MIN_INTENSITY, mask=inside)
    assert np.array_equal(by_lenslet.valid, lit & inside)


def test_relative_threshold_ignores_a_camera_offset(reference_frame) -> None:
    frame, _, lit = reference_frame
    centroider = Centroider.build(GRID, FRAME_SHAPE, min_intensity=MIN_INTENSITY)
    plain = centroider.measure(frame)
    shifted = centroider.measure(frame + np.uint16(400))
    assert np.array_equal(plain.valid, shifted.valid)
    assert np.allclose(plain.centroids[lit], shifted.centroids[lit], atol=1e-3)


def test_absolute_threshold_and_float_frames(aberrated_frame) -> None:
    frame, spots, lit = aberrated_frame
    measured = spots_of(
        frame.astype(np.float64) - BIAS,
        GRID,
        threshold=30.0,
        threshold_kind="absolute",
        min_intensity=MIN_INTENSITY,
    )
    assert np.array_equal(measured.valid, lit)
    assert np.abs(measured.centroids[lit] - spots[lit]).max() < 0.1


def reference_centroids(frame, grid, fraction):
    """Per-lenslet loop: the thresholded centre of gravity written out plainly."""
    row_starts, col_starts, width = grid.window_starts()
    out = np.full((grid.count, 2), np.nan)
    total = np.zeros(grid.count)
    for k, (r0, c0) in enumerate(zip(row_starts, col_starts)):
        window = frame[r0 : r0 + width, c0 : c0 + width].astype(np.float64)
        level = window.mean() + fraction * (window.max() - window.mean())
        weights = np.clip(window - level, 0.0, None)
        total[k] = weights.sum()
        if total[k] > 0:
            rr, cc = np.mgrid[r0 : r0 + width, c0 : c0 + width]
            out[k] = [(weights * cc).sum() / total[k], (weights * rr).sum() / total[k]]
    return out, total


@settings(max_examples=25, deadline=None)
@given(
    pitch=st.floats(4.0, 12.0),
    col=st.floats(-0.5, 6.0),
    row=st.floats(-0.5, 6.0),
    fraction=st.floats(0.0, 0.9),
    seed=st.integers(0, 2**16),
)
def test_vectorised_centroids_equal_the_plain_loop(pitch, col, row, fraction, seed) -> None:
    grid = square_array(pitch, (col, row), (3, 4))
    size = (int(3 * pitch) + 8, int(4 * pitch) + 8)
    frame = np.random.default_rng(seed).integers(0, 4000, size=size).astype(np.uint16)
    measured = spots_of(frame, grid, threshold=fraction)
    expected, total = reference_centroids(frame, grid, fraction)
    assert np.allclose(measured.intensity, total, rtol=1e-4, atol=1e-2)
    assert np.allclose(measured.centroids, expected, atol=1e-3, equal_nan=True)


def test_centroider_rejects_bad_input(reference_frame) -> None:
    frame, _, _ = reference_frame
    with pytest.raises(ValueError, match="leave the frame"):
        Centroider.build(GRID, (500, 500))
    with pytest.raises(ValueError, match="threshold"):
        Centroider.build(GRID, FRAME_SHAPE, threshold=1.5)
    with pytest.raises(ValueError, match="threshold_kind"):
        Centroider.build(GRID, FRAME_SHAPE, threshold_kind="otsu")
    with pytest.raises(ValueError, match="min_intensity"):
        Centroider.build(GRID, FRAME_SHAPE, min_intensity=-1.0)
    with pytest.raises(ValueError, match="mask"):
        Centroider.build(GRID, FRAME_SHAPE, mask=np.ones((3, 3), dtype=bool))
    with pytest.raises(ValueError, match="mask"):
        Centroider.build(GRID, FRAME_SHAPE, mask=np.ones(FRAME_SHAPE))
    with pytest.raises(ValueError, match="grid"):
        Centroider.build("grid", FRAME_SHAPE)
    centroider = Centroider.build(GRID, FRAME_SHAPE)
    with pytest.raises(ValueError, match="shape"):
        centroider.measure(frame[:-1])
    with pytest.raises(ValueError, match="real numbers"):
        centroider.measure(frame > 200)
    with pytest.raises(ValueError, match="2-D"):
        centroider.measure(frame[None])


# --------------------------------------------------------------------------- slopes and signs


@pytest.mark.parametrize("mode, axis, sign", [(1, 0, +1.0), (2, 1, -1.0)])
def test_sign_convention(mode, axis, sign) -> None:
    """+x tilt of W moves the spots to +col; +y tilt moves them to -row (up)."""
    coefficients = np.zeros(15)
    coefficients[mode] = 1.0  # Noll 2 = 2u (x tilt), Noll 3 = 2v (y tilt), um
    frame, _, lit = render(GRID, coefficients, seed=6)
    measured = spots_of(frame, GRID, min_intensity=MIN_INTENSITY)
    shift = (measured.centroids - GRID.centres())[lit]
    expected = 2.0 / pupil_of(GRID)[1] * FOCAL_UM / PIXEL_UM**2  # px of displacement
    # every spot sits at the same sub-pixel phase (0.66 px), so the centroid's S-curve bias
    # (~0.005 px at threshold 0.1) does not average out: 3 % allowed
    assert np.isclose(np.mean(shift[:, axis]), sign * expected, rtol=0.03)
    assert abs(np.mean(shift[:, 1 - axis])) < 0.01
    result = slopes(measured, GRID.centres(), FOCAL_UM, PIXEL_UM)
    along = result.slopes_x if axis == 0 else result.slopes_y
    across = result.slopes_y if axis == 0 else result.slopes_x
    rad = 2.0 / (pupil_of(GRID)[1] * PIXEL_UM)  # dW/dx with W and x in um
    assert np.isclose(np.mean(along[lit]), rad, rtol=0.02)
    assert abs(np.mean(across[lit])) < 0.01 * rad


def test_slopes_units_and_reference_forms(aberrated_frame) -> None:
    frame, _, lit = aberrated_frame
    measured = spots_of(frame, GRID, min_intensity=MIN_INTENSITY)
    from_grid = slopes(measured, GRID.centres(), FOCAL_UM, PIXEL_UM)
    assert np.array_equal(from_grid.valid, lit)
    assert np.all(np.isnan(from_grid.slopes_x[~lit]))
    displacement = measured.centroids[lit] - GRID.centres()[lit]
    assert np.allclose(from_grid.slopes_x[lit], displacement[:, 0] * PIXEL_UM / FOCAL_UM)
    assert np.allclose(from_grid.slopes_y[lit], -displacement[:, 1] * PIXEL_UM / FOCAL_UM)
    radius_um = pupil_of(GRID)[1] * PIXEL_UM
    wx, wy = convert_slopes(from_grid, wavefront_unit_um=0.6328, length_unit_um=radius_um)  # waves per radius
    assert np.allclose(wx[lit], from_grid.slopes_x[lit] * radius_um / 0.6328)
    assert np.allclose(wy[lit], from_grid.slopes_y[lit] * radius_um / 0.6328)
    # a reference measurement combines validity
    reference = SpotMeasurement(
        centroids=GRID.centres(),
        intensity=np.ones(GRID.count),
        valid=np.arange(GRID.count) % 2 == 0,
    )
    assert np.array_equal(slopes(measured, reference, FOCAL_UM, PIXEL_UM).valid, lit & reference.valid)


def test_slopes_reject_bad_input(reference_frame) -> None:
    frame, _, _ = reference_frame
    measured = spots_of(frame, GRID)
    with pytest.raises(ValueError, match="reference"):
        slopes(measured, np.zeros((10, 2)), FOCAL_UM, PIXEL_UM)
    with pytest.raises(ValueError, match="focal_length_um"):
        slopes(measured, GRID.centres(), 0.0, PIXEL_UM)
    with pytest.raises(ValueError, match="pixel_um"):
        slopes(measured, GRID.centres(), FOCAL_UM, float("nan"))
    with pytest.raises(ValueError, match="measurement"):
        slopes(frame, GRID.centres(), FOCAL_UM, PIXEL_UM)
    with pytest.raises(ValueError, match="wavefront_unit_um"):
        convert_slopes(slopes(measured, GRID.centres(), FOCAL_UM, PIXEL_UM), wavefront_unit_um=-1.0, length_unit_um=1.0)
    with pytest.raises(ValueError, match="centroids"):
        SpotMeasurement(centroids=np.zeros(4), intensity=np.zeros(4), valid=np.ones(4, dtype=bool))


# --------------------------------------------------------------------------- modal reconstruction


def test_modal_reconstruction_matches_truth(aberrated_slopes) -> None:
    sx, sy, valid = aberrated_slopes
    reconstructor = circle_reconstructor(valid)
    assert reconstructor.condition < 3.0
    coefficients = reconstructor.reconstruct(sx, sy)
    assert coefficients[0] == 0.0  # piston is not observable from slopes
    assert np.abs(coefficients - TRUTH).max() < MODAL_TOL_UM
    # the forward model reproduces the measured slopes to the noise level (~1e-4 um/px)
    model_x, model_y = reconstructor.predict(coefficients)
    assert np.sqrt(np.mean((model_x - sx)[valid] ** 2)) < 3e-4
    assert np.all(np.isnan(model_x[~valid]))


def test_modal_reconstruction_is_exact_for_quadratic_wavefronts() -> None:
    """Linear gradients: the subaperture mean is the centre value, no model error."""
    truth = np.zeros(15)
    truth[1:6] = [0.7, -0.2, 0.4, 0.3, -0.1]
    gx, gy = mean_gradient(GRID, truth)
    coefficients = circle_reconstructor(np.ones(GRID.count, dtype=bool)).reconstruct(gx, gy)
    assert np.allclose(coefficients, truth, atol=1e-12)


@pytest.fixture(scope="module")
def disk_map():
    (col0, row0), radius = pupil_of(GRID)
    rows, cols = np.mgrid[: FRAME_SHAPE[0], : FRAME_SHAPE[1]]
    mask = np.hypot(cols - col0, rows - row0) <= radius
    return csf_qcm_map(Aperture.from_mask(mask), target_vertices=8000)


def test_for_map_on_a_disk_agrees_with_for_circle(disk_map, aberrated_slopes) -> None:
    """The CSF-QCM map of a disk is a scaled identity up to discretisation, so the bases agree.

    Premise, checked first: the map moves no mesh vertex by more than 0.5 % of the radius from
    ``(p - c) / R`` (boundary polygon of the pixel disk, angular balancing, rotation fit). A
    displacement ``d`` of the canonical point changes ``Z`` by about ``d |grad Z|``, and the
    least-squares fit over 1256 lenslets averages the scattered per-triangle Jacobian errors,
    so the coefficients (up to 2 um) agree to 0.005 um (observed 1.4e-3 um).
    """
    (col0, row0), radius = pupil_of(GRID)
    identity = (disk_map.mesh.vertices - [col0, -row0]) / radius
    assert np.abs(disk_map.canonical - identity).max() < 5e-3
    sx, sy, valid = aberrated_slopes
    mapped = ModalReconstructor.for_map(GRID.centres_xy(), disk_map, MODES, valid)
    circle = circle_reconstructor(valid)
    assert mapped.reconstruct(sx, sy)[0] == 0.0
    assert np.abs(mapped.reconstruct(sx, sy) - circle.reconstruct(sx, sy)).max() < 5e-3


def test_for_map_on_an_annulus_uses_annular_zernikes() -> None:
    """Concentric annulus: the map is the scaled identity, the basis the annular Zernikes."""
    (col0, row0), radius = pupil_of(GRID)
    rows, cols = np.mgrid[: FRAME_SHAPE[0], : FRAME_SHAPE[1]]
    distance = np.hypot(cols - col0, rows - row0)
    annulus = (distance <= radius) & (distance >= 0.35 * radius)
    mapping = csf_qcm_map(Aperture.from_mask(annulus), target_vertices=6000)
    assert mapping.r_in == pytest.approx(0.35, abs=2e-3)
    centres = GRID.centres_xy()
    u, v = (centres[:, 0] - col0) / radius, (centres[:, 1] + row0) / radius
    valid = (np.hypot(u, v) <= 1 - 0.5 / 20) & (np.hypot(u, v) >= 0.35 + 0.5 / 20)
    truth = np.zeros(15)
    truth[1:6] = [1.0, -0.5, 0.3, 0.2, 0.1]
    grad_u, grad_v = annular_zernike_gradient(MODES, u, v, mapping.r_in)
    reconstructor = ModalReconstructor.for_map(centres, mapping, MODES, valid)
    coefficients = reconstructor.reconstruct(grad_u @ truth / radius, grad_v @ truth / radius)
    assert np.abs(coefficients - truth).max() < 5e-3


def test_modal_reconstructor_rejects_bad_input(aberrated_slopes) -> None:
    sx, sy, valid = aberrated_slopes
    centres = GRID.centres_xy()
    centre = (640.0, -512.0)
    with pytest.raises(ValueError, match="centres_xy"):
        ModalReconstructor.for_circle(centres[:, :1], centre, 500.0, MODES)
    with pytest.raises(ValueError, match="pupil_radius"):
        ModalReconstructor.for_circle(centres, centre, 0.0, MODES)
    with pytest.raises(ValueError, match="pupil_centre"):
        ModalReconstructor.for_circle(centres, (1.0,), 500.0, MODES)
    with pytest.raises(ValueError, match="valid"):
        ModalReconstructor.for_circle(centres, centre, 500.0, MODES, valid[:-1])
    with pytest.raises(ValueError, match="valid"):
        ModalReconstructor.for_circle(centres, centre, 500.0, MODES, np.zeros(GRID.count, dtype=bool))
    with pytest.raises(ValueError, match="modes"):
        ModalReconstructor.for_circle(centres, centre, 500.0, [])
    with pytest.raises(ValueError, match="even"):
        ModalReconstructor.for_circle(centres, centre, 500.0, [(2, 1)])
    few = np.zeros(GRID.count, dtype=bool)
    few[[820, 821]] = True
    with pytest.raises(ValueError, match="modes"):
        ModalReconstructor.for_circle(centres, centre, 500.0, MODES, few)
    with pytest.raises(ValueError, match="told apart"):
        ModalReconstructor.for_circle(centres, centre, 500.0, [(1, 1), (1, 1)])
    with pytest.raises(ValueError, match="mapping"):
        ModalReconstructor.for_map(centres, "disk", MODES)
    reconstructor = circle_reconstructor(valid)
    with pytest.raises(ValueError, match="shape"):
        reconstructor.reconstruct(sx[:-1], sy)
    broken = sx.copy()
    broken[np.flatnonzero(valid)[0]] = np.nan
    with pytest.raises(ValueError, match="finite"):
        reconstructor.reconstruct(broken, sy)
    with pytest.raises(ValueError, match="coefficients"):
        reconstructor.predict(np.zeros(3))


# --------------------------------------------------------------------------- zonal reconstruction


def test_southwell_matches_truth_up_to_piston(aberrated_slopes) -> None:
    sx, sy, valid = aberrated_slopes
    phase = southwell_reconstruct(sx, sy, valid.reshape(SHAPE), GRID.pitch_px)
    assert phase.shape == SHAPE
    assert np.all(np.isnan(phase.ravel()[~valid]))
    truth = wavefront_at_centres(GRID, TRUTH)[valid]
    error = phase.ravel()[valid] - (truth - truth.mean())
    assert abs(np.nanmean(phase)) < 1e-12
    assert np.sqrt(np.mean(error**2)) < ZONAL_RMS_TOL_UM
    assert np.abs(error).max() < ZONAL_MAX_TOL_UM


def test_southwell_is_exact_for_quadratic_wavefronts_and_accepts_grids() -> None:
    truth = np.zeros(15)
    truth[1:6] = [0.7, -0.2, 0.4, 0.3, -0.1]
    gx, gy = mean_gradient(GRID, truth)
    valid = np.ones(SHAPE, dtype=bool)
    reconstructor = SouthwellReconstructor.build(valid, GRID.pitch_px)
    expected = wavefront_at_centres(GRID, truth)
    phase = reconstructor.reconstruct(gx.reshape(SHAPE), gy.reshape(SHAPE))
    assert np.allclose(phase.ravel(), expected - expected.mean(), atol=1e-10)


def test_southwell_groups_and_isolated_lenslets() -> None:
    valid = np.zeros((6, 7), dtype=bool)
    valid[0:2, 0:3] = True  # group 1
    valid[4:6, 3:7] = True  # group 2
    valid[3, 0] = True  # no valid neighbour
    rows, cols = np.mgrid[0:6, 0:7]
    sx = np.full((6, 7), 0.1)  # dW/dx = 0.1 per unit, pitch 2: +0.2 per column
    sy = np.zeros((6, 7))
    reconstructor = SouthwellReconstructor.build(valid, 2.0)
    assert reconstructor.groups == 2
    assert not reconstructor.estimated[3, 0]
    phase = reconstructor.reconstruct(sx, sy)
    assert np.isnan(phase[3, 0]) and np.isnan(phase[2, 2])
    for group in (np.s_[0:2, 0:3], np.s_[4:6, 3:7]):
        assert abs(phase[group].mean()) < 1e-12
        ramp = 0.2 * cols[group]
        assert np.allclose(phase[group], ramp - ramp.mean())


def test_southwell_rejects_bad_input() -> None:
    valid = np.ones((4, 4), dtype=bool)
    with pytest.raises(ValueError, match="valid_grid"):
        SouthwellReconstructor.build(np.ones(16, dtype=bool), 1.0)
    with pytest.raises(ValueError, match="valid_grid"):
        SouthwellReconstructor.build(np.ones((4, 4)), 1.0)
    with pytest.raises(ValueError, match="pitch"):
        SouthwellReconstructor.build(valid, -1.0)
    with pytest.raises(ValueError, match="neighbour"):
        SouthwellReconstructor.build(np.eye(4, dtype=bool), 1.0)
    reconstructor = SouthwellReconstructor.build(valid, 1.0)
    with pytest.raises(ValueError, match="slopes_x"):
        reconstructor.reconstruct(np.zeros(15), np.zeros(16))
    with pytest.raises(ValueError, match="finite"):
        reconstructor.reconstruct(np.full(16, np.nan), np.zeros(16))
