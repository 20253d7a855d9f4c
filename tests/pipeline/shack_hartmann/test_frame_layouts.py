"""Frames in any memory layout the docstrings accept give the same spots as their C-contiguous copy."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.shack_hartmann import Centroider, LensletLattice, detect_lattice

# an integer pitch (the reshaped-crop path), a non-integer one (the gather path) and a turned
# array (one window per lenslet)
GRIDS = [LensletLattice.array("square", 10.0, (6, 7), first_centre_px=(7.0, 8.0)),
         LensletLattice.array("square", 10.4, (6, 7), first_centre_px=(6.5, 7.8)),
         LensletLattice.array("square", 10.0, (6, 7), first_centre_px=(7.0, 8.0), orientation_deg=0.5)]
SIZE = (70, 80)


def spot_frame(dtype: type, jitter_px: float = 1.5) -> np.ndarray:
    """Gaussian spots within ``jitter_px`` of the lenslet centres of GRIDS[0] on a noisy background, C order."""
    rng = np.random.default_rng(7)
    rows, cols = np.mgrid[: SIZE[0], : SIZE[1]]
    frame = 20.0 + rng.uniform(0.0, 5.0, SIZE)
    for col, row in GRIDS[0].centres() + rng.uniform(-jitter_px, jitter_px, (GRIDS[0].count, 2)):
        frame += 200.0 * np.exp(-((cols - col) ** 2 + (rows - row) ** 2) / (2 * 1.3**2))
    return frame.astype(dtype)


def layouts(frame: np.ndarray) -> dict[str, np.ndarray]:
    """The same pixels as ``frame`` in other memory layouts (each compares equal to it)."""
    doubled = np.zeros((2 * SIZE[0], 2 * SIZE[1]), frame.dtype)
    doubled[::2, ::2] = frame
    return {
        "fortran": np.asfortranarray(frame),  # e.g. scipy.io.loadmat of a MATLAB frame
        "transposed view": np.ascontiguousarray(frame.T).T,
        "strided view": doubled[::2, ::2],
        "negative stride": np.ascontiguousarray(frame[::-1])[::-1],
        "byte-swapped": frame.astype(frame.dtype.newbyteorder()),
    }


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32, np.float32, np.float64])
@pytest.mark.parametrize("grid", GRIDS, ids=["integer pitch", "non-integer pitch", "turned"])
@pytest.mark.parametrize("layout", ["fortran", "transposed view", "strided view", "negative stride", "byte-swapped"])
def test_centroids_do_not_depend_on_memory_layout(dtype, grid, layout) -> None:
    frame = spot_frame(dtype)
    other = layouts(frame)[layout]
    assert np.array_equal(other, frame)
    centroider = Centroider.build(grid, SIZE)
    expected = centroider.measure(frame)
    for measured in (centroider.measure(other), Centroider.build(grid, SIZE).measure(other)):
        # the same pixels go through the same arithmetic: identical, not merely close
        assert np.array_equal(measured.centroids, expected.centroids, equal_nan=True)
        assert np.array_equal(measured.intensity, expected.intensity)
        assert np.array_equal(measured.valid, expected.valid)
    assert expected.valid.all()


def _same(first: LensletLattice, second: LensletLattice) -> bool:
    return (first.kind == second.kind and first.basis_px == second.basis_px and first.origin_px == second.origin_px
            and np.array_equal(first.sites, second.sites))


def test_lattice_detection_does_not_depend_on_memory_layout() -> None:
    frame = spot_frame(np.uint16, jitter_px=0.3)  # spots on a lattice, as in a reference frame
    expected = detect_lattice(frame)
    assert _same(detect_lattice(np.asfortranarray(frame)), expected)
    assert _same(detect_lattice(np.ascontiguousarray(frame.T).T), expected)
