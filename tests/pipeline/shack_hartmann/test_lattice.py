"""Hexagonal (and square) lenslet lattices: detection, windows, slopes and modal reconstruction.

The synthetic sensor: a 512 x 512 camera (5.5 um pixels) behind a lenslet lattice of focal
length 5 mm, at 632.8 nm, so a wavefront slope of one wave per pixel moves a spot by
``gain = f lambda / p^2 = 104.6`` px. The pupil is a disk of radius 220 px; lenslets whose whole
cell lies inside it are lit. Each spot is a pixel-integrated Gaussian (sigma 1.5 px, 20000
photo-electrons) displaced by ``gain * <grad W>``, the wavefront gradient averaged over the
lenslet's own cell (its Voronoi cell, sampled on a 0.5 px grid), on a 100-count offset with
shot noise and 3-count read noise. Tolerances are derived in each test from quantities the
test computes (the measured centroid noise, the reconstructor's noise gain, the noise-free
model error).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import erf

from wavestack.pipeline.shack_hartmann import (
    Centroider, LensletLattice, ModalReconstructor, SpotMeasurement, convert_slopes, detect_lattice, slopes,
)
from wavestack.pipeline.zernike.circle import zernike_gradient
from wavestack.pipeline.zernike.indices import mode_list

SIZE = (512, 512)
FOCAL_UM, PIXEL_UM, WAVELENGTH_UM = 5000.0, 5.5, 0.6328
GAIN = FOCAL_UM * WAVELENGTH_UM / PIXEL_UM**2
PUPIL = (256.0, 250.0, 220.0)  # (col, row, radius), pixels
MODES = mode_list("noll", 15)
TRUTH = np.zeros(15)
TRUTH[[3, 5, 7]] = [0.5, -0.2, 0.25]  # waves: defocus, astigmatism, coma (Noll 4, 6, 8)
UNIT = {"square": np.array([[1.0, 0.0], [0.0, 1.0]]),
        "hexagonal": np.array([[1.0, 0.0], [0.5, 0.5 * math.sqrt(3.0)]])}


def spots_of(frame: np.ndarray, lattice: LensletLattice, **options) -> SpotMeasurement:
    """One frame's spots: a centroider built for its shape, then the measurement."""
    return Centroider.build(lattice, frame.shape, **options).measure(frame)


def lattice_of(kind: str, pitch: float, angle_deg: float) -> LensletLattice:
    """The lenslets of a lattice whose cells lie wholly inside the pupil, origin at the pupil centre."""
    a = math.radians(angle_deg)
    basis = pitch * UNIT[kind] @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    n = np.arange(-20, 21)
    sites = np.stack(np.meshgrid(n, n, indexing="ij"), axis=-1).reshape(-1, 2)
    centres = PUPIL[:2] + sites @ basis
    circumradius = pitch / math.sqrt(3.0) if kind == "hexagonal" else pitch / math.sqrt(2.0)
    inside = np.hypot(*(centres - PUPIL[:2]).T) <= PUPIL[2] - circumradius
    return LensletLattice(kind, tuple(map(tuple, basis)), PUPIL[:2], sites[inside])


def mean_gradient(lattice: LensletLattice, coefficients: np.ndarray) -> np.ndarray:
    """(dW/dx, dW/dy), waves per pixel, y up, averaged over each lenslet's Voronoi cell, (L, 2)."""
    step = 0.5
    half = lattice.pitch_px
    grid = np.arange(-half, half + step / 2, step)
    offsets = np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2)
    basis = np.asarray(lattice.basis_px)
    neighbours = np.array([basis[0], basis[1], basis[0] - basis[1]])
    neighbours = np.vstack([neighbours, -neighbours])
    # in the cell: no nearer to any neighbour than to the own centre
    cell = offsets[np.all(offsets @ neighbours.T <= 0.5 * np.sum(neighbours**2, axis=1), axis=1)]
    points = lattice.centres()[:, None, :] + cell[None]
    u = (points[..., 0] - PUPIL[0]).ravel() / PUPIL[2]
    v = -(points[..., 1] - PUPIL[1]).ravel() / PUPIL[2]
    grad_u, grad_v = zernike_gradient(MODES, u, v)
    per_point = np.column_stack([grad_u @ coefficients, grad_v @ coefficients]) / PUPIL[2]
    return per_point.reshape(lattice.count, len(cell), 2).mean(axis=1)


def render(centres: np.ndarray, seed: int, patch: int = 13) -> np.ndarray:
    """uint16 frame of Gaussian spots at ``centres`` ((col, row), px) with shot and read noise."""
    rng = np.random.default_rng(seed)
    start = np.rint(centres).astype(int) - patch // 2
    edges = np.arange(patch + 1) - 0.5

    def profile(position: np.ndarray, first: np.ndarray) -> np.ndarray:
        return 0.5 * np.diff(erf((first[:, None] + edges - position[:, None]) / (1.5 * np.sqrt(2))), axis=1)

    values = 20000.0 * profile(centres[:, 1], start[:, 1])[:, :, None] * profile(centres[:, 0], start[:, 0])[:, None, :]
    rows = start[:, 1, None, None] + np.arange(patch)[None, :, None]
    cols = start[:, 0, None, None] + np.arange(patch)[None, None, :]
    inside = (rows >= 0) & (rows < SIZE[0]) & (cols >= 0) & (cols < SIZE[1])
    flat = (rows * SIZE[1] + cols)[inside]
    expected = np.bincount(flat, weights=values[inside], minlength=SIZE[0] * SIZE[1]).reshape(SIZE)
    frame = rng.poisson(expected) + 100.0 + rng.normal(0.0, 3.0, SIZE)
    return np.clip(np.rint(frame), 0, 65535).astype(np.uint16)


def spot_positions(lattice: LensletLattice, coefficients: np.ndarray) -> np.ndarray:
    """Where the spots fall: displacement gain * (dW/dx, -dW/dy) from the lenslet centres."""
    return lattice.centres() + GAIN * mean_gradient(lattice, coefficients) * np.array([1.0, -1.0])


def matched(found: LensletLattice, truth: LensletLattice) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the found lattice and of the true lenslet nearest to each, (L, 2) each."""
    true = truth.centres()
    mine = found.centres()
    nearest = np.argmin(np.hypot(*(mine[:, None, :] - true[None, :, :]).transpose(2, 0, 1)), axis=1)
    return mine, true[nearest]


@pytest.mark.parametrize("kind, pitch, angle", [("hexagonal", 30.0, 0.0), ("hexagonal", 27.3, 7.0),
                                                ("hexagonal", 33.1, 90.0), ("square", 29.4, 3.0)])
def test_detected_lattice_matches_the_lenslets(kind, pitch, angle) -> None:
    truth = lattice_of(kind, pitch, angle)
    frame = render(truth.centres(), seed=1)
    found = detect_lattice(frame)
    assert found.kind == kind
    assert found.count == truth.count  # one lenslet per spot, none invented or lost
    centroids = spots_of(frame, truth).centroids
    noise = float(np.sqrt(np.mean((centroids - truth.centres()) ** 2)))  # per axis, px
    assert noise < 0.05  # photon and read noise, as the square chain measures (~0.015 px)
    # the lattice is fitted to all spots: each centre is better than one spot's centroid, so
    # 3 single-spot sigmas bound it with a margin
    mine, true = matched(found, truth)
    assert np.abs(mine - true).max() < 3 * noise
    assert found.pitch_px == pytest.approx(pitch, abs=3 * noise / 10)  # ... over >= 10 pitches
    symmetry = 60.0 if kind == "hexagonal" else 90.0
    turn = (found.orientation_deg - angle + symmetry / 2) % symmetry - symmetry / 2
    assert abs(turn) < math.degrees(3 * noise / (10 * pitch))


def test_a_square_array_is_detected_and_centroided_as_blocks() -> None:
    array = LensletLattice.array("square", 25.0, (20, 20), first_centre_px=(19.0, 13.0))
    assert array.rectangle() == (20, 20)  # the block layout: one window start per row and per column
    frame = render(array.centres(), seed=3)
    lattice = detect_lattice(frame)
    assert lattice.kind == "square" and lattice.count == array.count and abs(lattice.pitch_px - 25.0) < 1e-2
    mine, true = matched(lattice, array)
    assert np.abs(mine - true).max() < 0.05  # a fit to 400 spots, each centroided to ~0.015 px
    # the same lenslets in another order are centroided one window each: the same windows, the
    # same centroids, lenslet by lenslet
    order = np.random.default_rng(4).permutation(array.count)
    shuffled = array.with_sites(array.sites[order])
    assert shuffled.rectangle() is None and shuffled.window_width() == array.window_width() == 25
    assert np.array_equal(shuffled.window_starts()[0], array.window_starts()[0][order])
    by_blocks = spots_of(frame, array)
    one_by_one = spots_of(frame, shuffled)
    assert np.allclose(one_by_one.centroids, by_blocks.centroids[order], rtol=0, atol=1e-4)  # float32 sums
    assert np.allclose(one_by_one.intensity, by_blocks.intensity[order], rtol=1e-6)


def random_spots(rng: np.random.Generator, count: int, spacing: float) -> np.ndarray:
    """Poisson-disk-like random spots, at least ``spacing`` apart, inside the frame."""
    points: list[np.ndarray] = []
    while len(points) < count:
        candidate = rng.uniform(20, SIZE[0] - 20, 2)
        if all(np.hypot(*(candidate - p)) >= spacing for p in points):
            points.append(candidate)
    return np.array(points)


def superimposed_pitches() -> np.ndarray:
    """Two square arrays of 39.3 and 35.3 px pitch over one another."""
    first = LensletLattice.array("square", 39.3, (11, 11), first_centre_px=(39.65, 39.65)).centres()
    second = LensletLattice.array("square", 35.3, (12, 12), first_centre_px=(57.65, 49.65)).centres()
    return np.vstack([first, second])


@pytest.mark.parametrize("spots", [random_spots(np.random.default_rng(4), 150, 14.0), superimposed_pitches()],
                         ids=["random spots", "two pitches"])
def test_neither_square_nor_hexagonal_is_refused_with_the_reason(spots) -> None:
    frame = render(spots, seed=5)
    with pytest.raises(ValueError, match="expected") as error:
        detect_lattice(frame)
    message = str(error.value)
    assert "\n" not in message and message.startswith("frame: ")


@pytest.mark.parametrize("frame, reason", [(np.full(SIZE, 100.0), "no spots"),
                                           (render(np.array([[100.0, 100.0], [200.0, 300.0]]), 6), "found 2 spots")])
def test_too_few_spots_are_refused(frame, reason) -> None:
    with pytest.raises(ValueError, match=reason):
        detect_lattice(frame)


def pipeline_coefficients(lattice: LensletLattice, reference: np.ndarray, frame: np.ndarray,
                          ) -> tuple[np.ndarray, ModalReconstructor, np.ndarray]:
    """Coefficients (waves) from a spot frame against reference centroids, the reconstructor, the slopes."""
    centroider = Centroider.build(lattice, SIZE, min_intensity=3000.0)
    measured = centroider.measure(frame)
    reference_spots = centroider.measure(reference)
    result = slopes(measured, reference_spots, FOCAL_UM, PIXEL_UM)
    sx, sy = convert_slopes(result, wavefront_unit_um=WAVELENGTH_UM, length_unit_um=PIXEL_UM)
    reconstructor = ModalReconstructor.for_circle(lattice.centres_xy(), (PUPIL[0], -PUPIL[1]), PUPIL[2], MODES,
                                                  result.valid)
    return reconstructor.reconstruct(sx, sy), reconstructor, np.column_stack([sx, sy])


@pytest.mark.parametrize("angle", [0.0, 11.0])
def test_hexagonal_slopes_reconstruct_the_wavefront(angle) -> None:
    truth = lattice_of("hexagonal", 30.0, angle)
    reference = render(truth.centres(), seed=7)
    aberrated = render(spot_positions(truth, TRUTH), seed=8)
    lattice = detect_lattice(reference)
    assert lattice.kind == "hexagonal" and lattice.count == truth.count
    found, reconstructor, measured = pipeline_coefficients(lattice, reference, aberrated)
    assert reconstructor.valid.all()
    # Error budget, each part computed here:
    # 1. model: the spots follow the cell-mean gradient, the reconstructor the centre gradient;
    #    reconstruct the exact mean gradients of the found lenslets, noise-free
    exact = mean_gradient(lattice, TRUTH)
    model = np.abs(reconstructor.reconstruct(exact[:, 0], exact[:, 1]) - TRUTH)
    # 2. noise: the measured slope noise (spots of both frames) through the reconstructor's rows
    slope_noise = _slope_noise(lattice, truth, measured)
    gain = np.sqrt(np.sum(reconstructor.matrix**2, axis=1))  # coefficient sigma per unit slope sigma
    tolerance = model + 5.0 * slope_noise * gain + 1e-9
    assert np.all(np.abs(found - TRUTH) <= tolerance), (found - TRUTH, tolerance)
    assert np.abs(found - TRUTH).max() < 0.02  # and the budget itself is small: lambda / 50


def _slope_noise(lattice: LensletLattice, truth: LensletLattice, measured: np.ndarray) -> float:
    """RMS of measured minus true cell-mean slopes (waves per pixel), lenslets matched by position."""
    _, true_centres = matched(lattice, truth)
    index = np.argmin(np.hypot(*(true_centres[:, None, :] - truth.centres()[None]).transpose(2, 0, 1)), axis=1)
    true_slopes = mean_gradient(truth, TRUTH)[index]
    return float(np.sqrt(np.mean((measured - true_slopes) ** 2)))


@pytest.mark.parametrize("angle, seed", [(0.0, 9), (13.0, 10), (-41.0, 11)])
def test_lattice_windows_equal_the_plain_loop(angle, seed) -> None:
    lattice = lattice_of("hexagonal", 23.7, angle)
    frame = np.random.default_rng(seed).integers(0, 4000, size=SIZE).astype(np.uint16)
    measured = spots_of(frame, lattice, threshold=0.2)
    rows, cols, width = lattice.window_starts()
    assert width == math.floor(23.7 * 2 / (1 + math.sqrt(3)) + 1e-9) or angle != 0.0
    for k, (r0, c0) in enumerate(zip(rows, cols)):
        window = frame[r0: r0 + width, c0: c0 + width].astype(np.float64)
        weights = np.clip(window - (window.mean() + 0.2 * (window.max() - window.mean())), 0.0, None)
        rr, cc = np.mgrid[r0: r0 + width, c0: c0 + width]
        expected = [(weights * cc).sum() / weights.sum(), (weights * rr).sum() / weights.sum()]
        assert np.allclose(measured.centroids[k], expected, atol=1e-3)  # float32 sums
        assert measured.intensity[k] == pytest.approx(weights.sum(), rel=1e-4)


def test_windows_of_neighbours_never_overlap() -> None:
    for kind, angle in [("hexagonal", 0.0), ("hexagonal", 17.0), ("square", 0.0), ("square", 30.0)]:
        lattice = lattice_of(kind, 21.3, angle)
        rows, cols, width = lattice.window_starts()
        # two squares of side W overlap when both their row and column spans intersect
        apart = (np.abs(rows[:, None] - rows[None]) >= width) | (np.abs(cols[:, None] - cols[None]) >= width)
        np.fill_diagonal(apart, True)
        assert apart.all(), kind
    # the axis-aligned square lattice keeps the grid's full windows
    assert lattice_of("square", 21.3, 0.0).window_width() == 21


def test_lattice_rejects_bad_fields() -> None:
    hexagonal = ((20.0, 0.0), (10.0, 10.0 * math.sqrt(3.0)))
    with pytest.raises(ValueError, match="kind"):
        LensletLattice("triangular", hexagonal, (0.0, 0.0), [(0, 0)])
    with pytest.raises(ValueError, match="60 deg"):
        LensletLattice("hexagonal", ((20.0, 0.0), (0.0, 20.0)), (0.0, 0.0), [(0, 0)])
    with pytest.raises(ValueError, match="at least 4"):
        LensletLattice("square", ((2.0, 0.0), (0.0, 2.0)), (0.0, 0.0), [(0, 0)])
    with pytest.raises(ValueError, match="distinct"):
        LensletLattice("hexagonal", hexagonal, (0.0, 0.0), [(0, 0), (0, 0)])
    with pytest.raises(ValueError, match="integer"):
        LensletLattice("hexagonal", hexagonal, (0.0, 0.0), [(0.5, 0.0)])
    with pytest.raises(ValueError, match="origin_px"):
        LensletLattice("hexagonal", hexagonal, (0.0, math.nan), [(0, 0)])
    lattice = LensletLattice("hexagonal", hexagonal, (5.0, 5.0), [(0, 0)])
    with pytest.raises(ValueError, match="leave the frame"):
        lattice.check_fits((100, 100))
    with pytest.raises(ValueError, match="mask"):
        Centroider.build(lattice.with_sites([(2, 2)]), (100, 100), mask=np.ones((3, 3), dtype=bool))
