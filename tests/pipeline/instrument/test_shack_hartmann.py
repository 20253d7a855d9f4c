"""The Shack-Hartmann processor: its geometry (configured, auto, found), its explicit state, its refusals.

The synthetic sensor: a 400 x 440 camera behind a 25 px lenslet array (square 15 x 16, or
hexagonal 17 rows of 16), 5.5 um pixels, 5 mm focal length, 632.8 nm, so one wave per pixel of
slope moves a spot by ``gain = f lambda / p^2 = 104.6`` px. Spots are Gaussians (sigma 1.5 px,
peak 2000 counts) on a 100-count offset, drawn where a wavefront of known slopes puts them: at
``centre + gain * (dW/dx, -dW/dy)`` with the slopes taken at the lenslet centres, so the modal
reconstruction (gradients at the centres) has no model error and the coefficients come back to
the centroids' pixel-phase bias (~0.005 px on sigma 1.5 px spots, ``5e-5`` wave/px of slope).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavestack.pipeline.instrument import (
    ReconstructorCache, ShackHartmannProcessor, ShackHartmannSetup, cells_inside, configured_lattice,
    lenslet_geometry,
)
from wavestack.pipeline.shack_hartmann import LensletLattice, ModalReconstructor
from wavestack.pipeline.zernike.circle import zernike_basis, zernike_gradient
from wavestack.pipeline.zernike.indices import mode_list

SIZE = (400, 440)
SHAPES = {"square": (15, 16), "hexagonal": (17, 16)}
OFFSET = (20.0, 12.0)  # lenslet (0, 0) centred at (32.5, 24.5)
PUPIL = (220.0, 200.0, 170.0)  # col, row, radius
TRUTH = np.zeros(15)
TRUTH[[3, 4, 7]] = [0.4, -0.15, 0.1]  # waves: defocus, astigmatism, coma


def setup_for(kind: str, **changes) -> ShackHartmannSetup:
    fields = dict(focal_length_um=5000.0, pixel_um=5.5, wavelength_nm=632.8, lattice=kind, pitch_px=25.0,
                  offset_px=OFFSET, grid_shape=SHAPES["square" if kind == "auto" else kind], pupil_px=PUPIL,
                  modes=15, min_intensity=2000.0)
    return ShackHartmannSetup(**{**fields, **changes})


def array_of(kind: str) -> LensletLattice:
    return LensletLattice.array(kind, 25.0, SHAPES[kind], first_centre_px=(OFFSET[0] + 12.5, OFFSET[1] + 12.5))


def spots(centres: np.ndarray, seed: int = 0) -> np.ndarray:
    """A uint16 frame of Gaussian spots at ``centres`` ((col, row), px) with read noise."""
    rows, cols = np.mgrid[: SIZE[0], : SIZE[1]]
    frame = 100.0 + np.random.default_rng(seed).normal(0.0, 2.0, SIZE)
    for col, row in centres:
        near = slice(max(int(row) - 7, 0), int(row) + 8), slice(max(int(col) - 7, 0), int(col) + 8)
        frame[near] += 2000.0 * np.exp(-((cols[near] - col) ** 2 + (rows[near] - row) ** 2) / (2 * 1.5**2))
    return np.clip(np.rint(frame), 0, 65535).astype(np.uint16)


def aberrated(lattice: LensletLattice, coefficients: np.ndarray = TRUTH) -> np.ndarray:
    """Where the spots fall for a wavefront of these coefficients (unit RMS over PUPIL, waves), (L, 2)."""
    gain = 5000.0 * 0.6328 / 5.5**2
    centres = lattice.centres()
    u, v = (centres[:, 0] - PUPIL[0]) / PUPIL[2], -(centres[:, 1] - PUPIL[1]) / PUPIL[2]
    grad_u, grad_v = zernike_gradient(mode_list("noll", 15), u, v)
    slopes = np.column_stack([grad_u @ coefficients, grad_v @ coefficients]) / PUPIL[2]  # waves per px, y up
    return centres + gain * slopes * np.array([1.0, -1.0])


@pytest.mark.parametrize("kind", ["square", "hexagonal"])
def test_the_configured_array_gives_the_wavefront(kind: str) -> None:
    processor = ShackHartmannProcessor(setup_for(kind))
    assert processor.state.geometry is None  # nothing is known before the first frame
    outcome = processor.process([spots(aberrated(array_of(kind)))])
    assert outcome.valid, outcome.reason
    geometry = processor.state.geometry
    assert geometry.lattice.kind == kind and geometry.lattice.count == math.prod(SHAPES[kind])
    # every lenslet whose whole cell lies in the pupil disk is lit: the spots are alike
    assert outcome.diagnostics.lit_lenslets == outcome.diagnostics.pupil_lenslets == int(geometry.in_pupil.sum())
    # centroid bias <= 0.01 px -> slope error <= 1e-4 wave/px, times the reconstructor's row norms
    # (< 20 px per unit slope here, computed in the module notes' geometry): 2e-3 waves
    assert np.abs(outcome.coefficients_waves - TRUTH).max() < 2e-3
    assert outcome.tilt_measured and outcome.pupil_px == PUPIL


@pytest.mark.parametrize("kind", ["square", "hexagonal"])
def test_auto_takes_the_kind_from_the_reference_frame(kind: str) -> None:
    setup = setup_for("auto", grid_shape=SHAPES[kind])
    geometry = lenslet_geometry(setup, SIZE, spots(aberrated(array_of(kind))))
    assert geometry.lattice.kind == kind
    expected = configured_lattice(setup, kind, SIZE)
    assert np.array_equal(geometry.lattice.centres(), expected.centres())  # the configured array, not a fit
    assert ShackHartmannProcessor(setup).process([spots(aberrated(array_of(kind)))]).valid


def test_auto_refuses_spots_the_configured_array_does_not_explain() -> None:
    # a hexagonal array half a pitch right of the configured one: a hexagonal lattice, but every
    # spot sits half a pitch from the configured lenslets
    shifted = array_of("hexagonal").centres() + np.array([12.5, 0.0])
    outcome = ShackHartmannProcessor(setup_for("auto", grid_shape=SHAPES["hexagonal"])).process([spots(shifted)])
    assert not outcome.valid and outcome.reason.startswith("lattice: the reference frame's spots lie on a hexagonal")
    assert "within 0.25 pitch" in outcome.reason and "\n" not in outcome.reason


def test_auto_refuses_spots_on_no_lattice() -> None:
    rng = np.random.default_rng(3)
    scattered = rng.uniform([20, 20], [SIZE[1] - 20, SIZE[0] - 20], (150, 2))
    outcome = ShackHartmannProcessor(setup_for("auto")).process([spots(scattered)])
    assert not outcome.valid and outcome.reason.startswith("lattice: ") and "expected" in outcome.reason
    assert outcome.coefficients_waves is None


def test_the_state_and_the_reconstructor_cache_are_explicit() -> None:
    cache = ReconstructorCache(2)
    processor = ShackHartmannProcessor(setup_for("square"), reconstructors=cache)
    full = aberrated(array_of("square"))
    dark_corner = full.copy()
    dark_corner[:40] = -100.0  # the top rows' spots off the frame: their lenslets go dark
    first, second, third = (processor.process([spots(centres, seed)]) for seed, centres in
                            ((1, full), (2, dark_corner), (3, full)))
    assert [o.aperture_changed for o in (first, second, third)] == [True, True, True]
    assert [o.aperture_record.id for o in (first, second, third)] == [0, 1, 2]
    assert processor.state.lit_sets == 2 and cache.builds == 2  # the third frame reuses the first set's
    assert second.diagnostics.lit_lenslets < first.diagnostics.lit_lenslets


def test_a_frame_without_spots_is_invalid() -> None:
    processor = ShackHartmannProcessor(setup_for("square", min_intensity=0.0),
                                       reference_frame=spots(array_of("square").centres()))
    outcome = processor.process([spots(np.empty((0, 2)))])
    assert not outcome.valid and outcome.reason.startswith("lenslets: no spots")


def test_a_lattice_placed_on_the_spots_measures_no_tilt() -> None:
    tilted = TRUTH.copy()
    tilted[1] = 0.3
    setup = setup_for("auto", offset_px=None, grid_shape=None)
    processor = ShackHartmannProcessor(setup)
    positions = aberrated(array_of("hexagonal"), tilted)
    outcome = processor.process([spots(positions)])
    assert outcome.valid and not outcome.tilt_measured
    assert outcome.coefficients_waves[1] == outcome.coefficients_waves[2] == 0.0
    # The lattice is a similarity fitted to the aberrated spots: its origin takes the mean
    # displacement (tilt, not measured), its turn the rotation part of the displacement field over
    # an array not centred on the pupil. What that geometry gives on the exact spot positions ...
    geometry = processor.state.geometry
    lit = outcome.lenslets.lit
    centres = geometry.lattice.centres()
    exact = positions[np.argmin(np.hypot(*(centres[:, None] - positions[None]).transpose(2, 0, 1)), axis=1)]
    slopes = (exact - centres) * np.array([1.0, -1.0]) / setup.gain_px
    reconstructor = ModalReconstructor.for_circle(geometry.lattice.centres_xy(), (PUPIL[0], -PUPIL[1]), PUPIL[2],
                                                  mode_list("noll", 15), lit)
    model = reconstructor.reconstruct(slopes[:, 0], slopes[:, 1])
    # ... is what the processor gives, to the centroid bias (2e-3 waves, as above) ...
    assert np.abs(outcome.coefficients_waves[3:] - model[3:]).max() < 2e-3
    # ... and the geometry costs little: measured 2.7e-3 waves for a 2e-4 rad turn
    assert np.abs(model[3:] - TRUTH[3:]).max() < 5e-3
    assert abs(math.radians(geometry.lattice.orientation_deg)) < 1e-3


def test_cells_inside_a_disk() -> None:
    hexagonal = LensletLattice.array("hexagonal", 20.0, (1, 1), first_centre_px=(0.0, 0.0))
    square = LensletLattice.array("square", 20.0, (1, 1), first_centre_px=(0.0, 0.0))
    # a hexagon's corners are pitch / sqrt(3) from its centre, a square's pitch / sqrt(2)
    assert cells_inside(hexagonal, (0.0, 0.0, 20 / math.sqrt(3) + 1e-9))[0]
    assert not cells_inside(hexagonal, (0.0, 0.0, 20 / math.sqrt(3) - 1e-6))[0]
    assert not cells_inside(square, (0.0, 0.0, 20 / math.sqrt(3) + 1e-9))[0]


@pytest.mark.parametrize("changes, word", [
    (dict(lattice="triangular"), "lattice"),
    (dict(pitch_px=None), "pitch_px"),
    (dict(pitch_px=3.0), "pitch_px"),
    (dict(reference="flat"), "reference"),
    (dict(lit_fraction=1.5), "lit_fraction"),
    (dict(pupil_px=(0.0, 0.0, 0.0)), "pupil_px"),
    (dict(ordering="zygo"), "ordering"),
    (dict(reconstructor_cache=0), "reconstructor_cache"),
])
def test_the_setup_refuses_bad_fields(changes: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        setup_for("square", **changes)
    with pytest.raises(ValueError, match="reference_frame"):
        ShackHartmannProcessor(setup_for("square", reference="frame"))


def test_the_wavefront_pv_is_the_reconstruction_less_piston_and_tilt_at_the_lit_lenslets() -> None:
    processor = ShackHartmannProcessor(setup_for("square"))
    outcome = processor.process([spots(aberrated(array_of("square")))])
    assert outcome.valid, outcome.reason
    centres = processor.state.geometry.lattice.centres()[outcome.lenslets.lit]
    u, v = (centres[:, 0] - PUPIL[0]) / PUPIL[2], -(centres[:, 1] - PUPIL[1]) / PUPIL[2]
    modes = mode_list("noll", 15)
    higher = [k for k, (n, _) in enumerate(modes) if n >= 2]
    true_map = zernike_basis([modes[k] for k in higher], u, v) @ TRUTH[higher]
    figures = outcome.statistics
    # coefficients within 2e-3 waves of the truth (the test above), times at most ~3 for the
    # largest of these 12 unit-RMS terms at a lenslet centre inside the pupil: 0.03 waves at most
    assert figures.pv == pytest.approx(float(np.ptp(true_map)), abs=0.03)
    assert figures.pv > 1.0 and math.isnan(figures.pvr)  # no map, no PVr
