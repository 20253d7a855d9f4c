"""Tests for the simulated optic's surface: settings, the thread-safe height map, roughness, map sources.

Tolerances
----------
* Roughness RMS and piston: the field is scaled to the requested RMS over the aperture exactly,
  so they hold to rounding (1e-9 relative).
* Roughness correlation length: over 20 seeds on a 256 x 256 grid with ``l = 5 px`` the normalised
  autocorrelation at lag ``l`` (mean of the row and column lags) measured 0.362 +- 0.011 (1/e =
  0.368; the estimate is biased low by the piston removal, ~1 / (number of correlation areas)).
  Bound: 0.05 (4.5 standard deviations); at ``2 l``, exp(-4) = 0.018 measured +- 0.019: bound 0.08.
* A plane mapped from a ``.npy`` file: bilinear resampling reproduces a linear function exactly,
  so inside the measured disk the heights are the plane to rounding (1e-9 nm); a harmonic fill of
  a hole in a plane is the plane too (the sparse solve's rounding: 1e-6 nm).
"""

from __future__ import annotations

import doctest
import math
import threading
from pathlib import Path

import numpy as np
import pytest
import scipy.ndimage

from shared_data import DATA, require_shared_data
from wavestack.pipeline import Aperture, read_measured_map
from wavestack.simulators import SurfaceSettings, SurfaceState
from wavestack.simulators import roughness, surface, surface_settings
from wavestack.simulators.aperture_shape import ApertureShape
from wavestack.simulators.roughness import gaussian_random_field
from wavestack.simulators.surface_sources import initial_heights_nm, measured_surface_nm, zernike_surface_nm

ZYGO = DATA / "zygo-dat" / "valid_zygo_dat_file.dat"
SIZE = 256
CIRCLE = ApertureShape(centre_px=(130.3, 124.8), radius_px=100.0)


@pytest.mark.parametrize("module", [surface, surface_settings, roughness], ids=lambda m: m.__name__)
def test_examples_run(module) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


# --------------------------------------------------------------------------- settings


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(zernike_nm=(0.0, math.nan)), r"zernike_nm\[1\]"),
        (dict(map_file="scan.txt"), "map_file"),
        (dict(map_file=""), "map_file"),
        (dict(map_rms_nm=10.0), "map_rms_nm: given without map_file"),
        (dict(map_file="a.npy", map_rms_nm=0.0), "map_rms_nm"),
        (dict(roughness_rms_nm=-1.0), "roughness_rms_nm"),
        (dict(roughness_rms_nm=1.0, roughness_correlation_mm=0.05, pixel_mm=0.1), "roughness_correlation_mm"),
        (dict(roughness_correlation_mm=0.0), "roughness_correlation_mm"),
        (dict(pixel_mm=0.0), "pixel_mm"),
        (dict(reflection_factor=-2.0), "reflection_factor"),
        (dict(wavelength_nm=math.inf), "wavelength_nm"),
        (dict(seed=-1), "seed"),
    ],
)
def test_surface_settings_reject_bad_fields(kwargs: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        SurfaceSettings(**kwargs)


# --------------------------------------------------------------------------- the height map


def test_snapshots_are_read_only_and_never_change() -> None:
    start = np.arange(12.0).reshape(3, 4)
    state = SurfaceState(start, pixel_mm=0.2)
    start[0, 0] = 99.0  # the state copied its input
    first = state.heights_nm()
    assert state.shape == (3, 4) and state.pixel_mm == 0.2 and state.revision == 0 and first[0, 0] == 0.0
    with pytest.raises(ValueError):
        first[0, 0] = 1.0
    removal = np.full((3, 4), 0.5)
    state.apply_removal(removal)
    assert state.revision == 1
    np.testing.assert_array_equal(first, np.arange(12.0).reshape(3, 4))  # the old snapshot is untouched
    np.testing.assert_array_equal(state.heights_nm(), first - 0.5)
    assert state.snapshot().revision == 1 and state.snapshot().heights_nm is state.heights_nm()


@pytest.mark.parametrize(
    "removal, word",
    [
        (np.zeros((3, 5)), r"removal_nm: expected shape \(3, 4\)"),
        (np.zeros(12), "removal_nm: expected a 2-D array"),
        (np.full((3, 4), np.nan), "removal_nm: expected finite values, got 12 NaN"),
        (np.zeros((3, 4), dtype=complex), "removal_nm: expected a real array"),
        (np.zeros((3, 4), dtype=bool), "removal_nm: expected a real array"),
        ("deep", "removal_nm: expected a real array"),
    ],
)
def test_apply_removal_refuses_bad_input_and_changes_nothing(removal, word: str) -> None:
    state = SurfaceState(np.ones((3, 4)), pixel_mm=0.1)
    before = state.heights_nm()
    with pytest.raises(ValueError, match=word):
        state.apply_removal(removal)
    assert state.revision == 0 and state.heights_nm() is before


@pytest.mark.parametrize("heights, pixel, word", [(np.full((2, 2), np.inf), 0.1, "heights_nm"),
                                                  (np.zeros((2, 2)), 0.0, "pixel_mm")])
def test_state_refuses_bad_construction(heights, pixel: float, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        SurfaceState(heights, pixel)


def test_concurrent_removals_are_never_lost() -> None:
    threads_n, each = 8, 25
    state = SurfaceState(np.zeros((64, 64)), pixel_mm=0.1)
    removals = [np.random.default_rng(k).uniform(0.0, 1.0, (each, 64, 64)) for k in range(threads_n)]
    start = threading.Barrier(threads_n + 1)
    seen: list[tuple[np.ndarray, np.ndarray]] = []  # (snapshot, a copy taken when it was handed out)
    done = threading.Event()

    def polish(stack: np.ndarray) -> None:
        start.wait(timeout=30)
        for removal in stack:
            state.apply_removal(removal)

    def read() -> None:
        start.wait(timeout=30)
        while not done.is_set() and len(seen) < 200:
            snapshot = state.heights_nm()
            seen.append((snapshot, snapshot.copy()))

    workers = [threading.Thread(target=polish, args=(stack,)) for stack in removals]
    reader = threading.Thread(target=read)
    for thread in [*workers, reader]:
        thread.start()
    for thread in workers:
        thread.join(timeout=60)
    done.set()
    reader.join(timeout=60)
    assert not any(thread.is_alive() for thread in [*workers, reader])
    assert state.revision == threads_n * each
    # the same sums in another order: equal to float64 rounding (200 terms of <= 1 nm)
    np.testing.assert_allclose(state.heights_nm(), -sum(stack.sum(axis=0) for stack in removals), atol=1e-9)
    assert seen and all(np.array_equal(snapshot, copy) for snapshot, copy in seen)


# --------------------------------------------------------------------------- roughness


def autocorrelation(field: np.ndarray, lag: int) -> float:
    """Normalised autocorrelation at ``lag`` pixels, the mean of the row and column lags."""
    field = field - field.mean()
    pairs = np.mean(field[:, :-lag] * field[:, lag:]) + np.mean(field[:-lag] * field[lag:])
    return float(pairs / (2.0 * np.mean(field**2)))


def test_roughness_has_the_requested_rms_and_correlation_length() -> None:
    mask = CIRCLE.mask(SIZE, SIZE)
    settings = SurfaceSettings(roughness_rms_nm=2.5, roughness_correlation_mm=0.5, pixel_mm=0.1, seed=3)
    field = initial_heights_nm(settings, mask)
    assert np.isfinite(field).all() and field.shape == (SIZE, SIZE)
    assert math.isclose(float(np.sqrt(np.mean(field[mask] ** 2))), 2.5, rel_tol=1e-9)
    assert abs(float(field[mask].mean())) < 1e-9
    length = round(0.5 / 0.1)  # 5 px
    assert abs(autocorrelation(field, length) - math.exp(-1.0)) < 0.05
    assert abs(autocorrelation(field, 2 * length) - math.exp(-4.0)) < 0.08
    # a field twice as long-correlated is measurably different (the test can tell them apart)
    longer = gaussian_random_field(mask, rms_nm=2.5, correlation_px=2 * length, seed=3)
    assert abs(autocorrelation(longer, length) - math.exp(-0.25)) < 0.08


def test_roughness_is_seeded() -> None:
    mask = np.ones((32, 40), dtype=bool)
    one = gaussian_random_field(mask, rms_nm=1.0, correlation_px=3.0, seed=7)
    np.testing.assert_array_equal(one, gaussian_random_field(mask, rms_nm=1.0, correlation_px=3.0, seed=7))
    assert not np.allclose(one, gaussian_random_field(mask, rms_nm=1.0, correlation_px=3.0, seed=8))
    assert not gaussian_random_field(mask, rms_nm=0.0, correlation_px=3.0, seed=7).any()


# --------------------------------------------------------------------------- Zernike terms


def test_zernike_surface_is_the_optic_basis_inside_and_radially_constant_outside() -> None:
    mask = CIRCLE.mask(SIZE, SIZE)
    heights = zernike_surface_nm((0.0, 0.0, 0.0, 20.0), mask)
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    rows, cols = np.indices(mask.shape)
    rho2 = ((cols - cx) ** 2 + (cy - rows) ** 2) / radius**2
    inside = rho2 <= 1.0
    np.testing.assert_allclose(heights[inside], 20.0 * math.sqrt(3.0) * (2.0 * rho2[inside] - 1.0), atol=1e-9)
    np.testing.assert_allclose(heights[~inside], 20.0 * math.sqrt(3.0), atol=1e-9)  # the edge value


# --------------------------------------------------------------------------- measured maps


def plane_file(tmp_path: Path, hole: bool) -> tuple[Path, np.ndarray]:
    rows, cols = np.indices((100, 110), dtype=np.float64)
    source = 0.7 * cols - 0.3 * rows  # nm; x right, rows down
    valid = (cols - 52.0) ** 2 + (rows - 47.0) ** 2 <= 40.0**2
    if hole:
        valid &= (cols - 60.0) ** 2 + (rows - 40.0) ** 2 > 3.0**2
    path = tmp_path / "plane.npy"
    np.save(path, np.where(valid, source, np.nan))
    return path, valid


def test_a_plane_map_lands_on_the_aperture_disk(tmp_path: Path) -> None:
    path, valid = plane_file(tmp_path, hole=False)
    mask = CIRCLE.mask(SIZE, SIZE)
    heights = measured_surface_nm(path, mask, None)
    src_cx, src_cy, src_radius = Aperture.from_mask(valid).enclosing_circle()
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    scale = radius / src_radius
    rows, cols = np.indices(mask.shape, dtype=np.float64)
    expected = 0.7 * (src_cx + (cols - cx) / scale) - 0.3 * (src_cy + (rows - cy) / scale)
    well_inside = (cols - cx) ** 2 + (rows - cy) ** 2 <= (0.95 * radius) ** 2
    difference = heights[well_inside] - expected[well_inside]
    assert np.ptp(difference) < 1e-9  # the plane, up to the piston (set over the aperture's filled rim too)
    assert np.isfinite(heights).all()


def test_holes_are_filled_smoothly_and_the_rms_is_the_target(tmp_path: Path) -> None:
    path, _ = plane_file(tmp_path, hole=True)
    mask = CIRCLE.mask(SIZE, SIZE)
    heights = measured_surface_nm(path, mask, 12.0)
    assert np.isfinite(heights).all()
    assert math.isclose(float(np.sqrt(np.mean(heights[mask] ** 2))), 12.0, rel_tol=1e-9)
    # the filled hole continues the plane: a plane fit well inside the aperture leaves little residual
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    rows, cols = np.nonzero(mask)
    inside = (cols - cx) ** 2 + (rows - cy) ** 2 <= (0.95 * radius) ** 2
    rows, cols = rows[inside], cols[inside]
    design = np.column_stack([np.ones(rows.size), cols, rows])
    residual = heights[rows, cols] - design @ np.linalg.lstsq(design, heights[rows, cols], rcond=None)[0]
    # a harmonic fill of a plane is the plane (bilinear resampling keeps it): rounding only
    assert np.max(np.abs(residual)) < 1e-6


def test_flat_map_cannot_be_scaled(tmp_path: Path) -> None:
    path = tmp_path / "flat.npy"
    np.save(path, np.full((20, 20), 5.0))
    with pytest.raises(ValueError, match="flat.npy: the map is flat over the aperture"):
        measured_surface_nm(path, CIRCLE.mask(SIZE, SIZE), 10.0)


@require_shared_data()
def test_zygo_map_reaches_the_target_rms_with_its_structure() -> None:
    mask = CIRCLE.mask(SIZE, SIZE)
    settings = SurfaceSettings(map_file=str(ZYGO), map_rms_nm=50.0)
    heights = initial_heights_nm(settings, mask)
    assert np.isfinite(heights).all()
    assert math.isclose(float(np.sqrt(np.mean(heights[mask] ** 2))), 50.0, rel_tol=1e-9)
    assert abs(float(heights[mask].mean())) < 1e-9
    # the original resampled independently (nearest source pixel) where it was measured
    original = read_measured_map(ZYGO)
    src_cx, src_cy, src_radius = Aperture.from_mask(original.valid).enclosing_circle()
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    rows, cols = np.nonzero(mask)
    src_rows = np.rint(src_cy + (rows - cy) * src_radius / radius).astype(int)
    src_cols = np.rint(src_cx + (cols - cx) * src_radius / radius).astype(int)
    inside = (src_rows >= 0) & (src_rows < original.valid.shape[0]) & (src_cols >= 0) & (src_cols < original.valid.shape[1])
    measured = np.zeros(rows.size, dtype=bool)
    measured[inside] = original.valid[src_rows[inside], src_cols[inside]]
    assert measured.mean() > 0.8  # most of the aperture shows measured pixels
    reference = original.map_nm[src_rows[measured], src_cols[measured]]
    correlation = np.corrcoef(heights[rows[measured], cols[measured]], reference)[0, 1]
    assert correlation > 0.9
    # the same heights turned by 90 degrees correlate less: the placement is what matches, not the statistics
    turned = scipy.ndimage.rotate(heights, 90.0, reshape=False, order=1, mode="nearest")
    assert np.corrcoef(turned[rows[measured], cols[measured]], reference)[0, 1] < correlation
