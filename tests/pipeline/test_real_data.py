"""Acceptance on real measured data (../shared/data): a 152.2 mm f/4 mirror and a Zygo map.

The mirror was tested at its centre of curvature (R = 1215 mm) at 654 nm without a null, so
the wavefront carries a large spherical term. Two 6-frame cycles (Image5-10, Image11-16) are
independent measurements; a tilted 6-frame set (Image2282-2287) and one carrier frame
(Image197) measure the same figure another way.
"""

from __future__ import annotations


import numpy as np
import pytest

from wavestack.pipeline import Aperture, build_fitter
from wavestack.pipeline import ConicTest, implied_conic_constant
from wavestack.pipeline import read_frame, read_frame_set
from wavestack.pipeline import wavefront_from_carrier, wavefront_from_phase_shifts
from wavestack.pipeline import read_metropro_dat

from shared_data import DATA, require_shared_data

PSI = DATA / "psi-mirror-654nm"
MIRROR = ConicTest(radius_of_curvature_mm=1215.0, diameter_mm=152.2, wavelength_nm=654.0)
MODES = 15

pytestmark = require_shared_data()


def _coefficients(measured) -> np.ndarray:
    fitter = build_fitter(measured.aperture, modes=MODES, dtype=np.float64)
    return fitter.fit(measured.waves, nan_policy="omit").coefficients


@pytest.fixture(scope="module")
def cycles():
    first = read_frame_set([PSI / f"Image{i}.jpg" for i in range(5, 11)])
    second = read_frame_set([PSI / f"Image{i}.jpg" for i in range(11, 17)])
    return [wavefront_from_phase_shifts(frames, method="aia") for frames in (first, second)]


def test_estimated_steps_are_near_the_nominal_sixty_degrees(cycles) -> None:
    for measured in cycles:
        steps = np.rad2deg(measured.steps_rad)
        # measured 0/65/124/185/243/303 and 0/59/119/182/237/300 degrees: real steps deviate
        # from nominal by up to ~6 degrees, which is why the step-estimating AIA is used
        assert np.all(np.abs(steps - 60.0 * np.arange(6)) < 10.0)


def test_the_two_cycles_agree_far_better_than_the_figure(cycles) -> None:
    a, b = (_coefficients(m) for m in cycles)
    figure = a[3:]  # after piston and tilt
    difference = a[3:] - b[3:]
    # Measured: terms up to 0.47 waves, differences at most ~0.005 waves (air and vibration
    # between cycles, JPEG noise). Bound: the difference below 5 % of the figure's RMS and
    # below 0.01 waves in every term; a sign or ordering error would break both.
    assert np.sqrt(np.mean(difference**2)) < 0.05 * np.sqrt(np.mean(figure**2))
    assert np.max(np.abs(difference)) < 0.01


def test_spherical_term_and_implied_conic_are_consistent(cycles) -> None:
    spherical = [_coefficients(m)[10] for m in cycles]
    conics = [implied_conic_constant(s, MIRROR) for s in spherical]
    # Measured Z11 = 0.451 and 0.451 waves, K = -0.846 and -0.847 under our sign convention, on
    # the detected aperture (half-way edge). Before the half-way rule: 0.470 and 0.469, K = -0.883
    # and -0.880, with a pupil 4 px too wide from a piece of halo at the left rim.
    assert abs(spherical[0] - spherical[1]) < 0.01
    assert abs(conics[0] - conics[1]) < 0.02
    assert all(s > 0.3 for s in spherical)  # a large spherical term, as the setup promises


def test_tilted_set_measures_the_same_spherical(cycles) -> None:
    tilted = read_frame_set([PSI / f"Image{i}.jpg" for i in range(2282, 2288)])
    measured = wavefront_from_phase_shifts(tilted, method="aia")
    spherical = _coefficients(measured)[10]
    reference = np.mean([_coefficients(m)[10] for m in cycles])
    # Measured 0.460 against 0.451: the detected aperture differs by about a pixel between the
    # sets (enclosing radius 286.7 vs 285.5 px: the tilted set's rim bulges at the upper right)
    # and Z11 scales with the fourth power of the pupil radius. See the circle choice below.
    assert spherical == pytest.approx(reference, rel=0.05)


def test_carrier_frame_measures_the_spherical_on_the_same_pupil_as_the_cycles(cycles) -> None:
    frame = read_frame(PSI / "Image197.jpg")
    # One frame cannot tell phi from -phi; this setup's tilt needs sign -1 to match the
    # phase-shifted cycles (with +1 every coefficient flips sign).
    measured = wavefront_from_carrier(frame, sign=-1)
    assert measured.aperture.valid_count > 200_000  # the whole mirror, found from fringe variance
    # Compare like with like: Z11 scales with the pupil radius to the fourth power, and the
    # carrier aperture's enclosing circle (301.1 px: halo at the frame's top and bottom edges
    # passes the variance threshold) is not the cycles' (285.5 px). One fitter on the pixels all
    # three share.
    common = measured.aperture.mask & cycles[0].aperture.mask & cycles[1].aperture.mask
    fitter = build_fitter(Aperture.from_mask(common), modes=MODES, dtype=np.float64)
    spherical = fitter.fit(measured.waves, nan_policy="omit").coefficients[10]
    reference = np.mean([fitter.fit(m.waves, nan_policy="omit").coefficients[10] for m in cycles])
    # Measured 0.431 against 0.449 (4 % low; 0.432 against 0.461, 6 % low, on the common
    # region before the half-way edge, when the carrier aperture was an eroded contrast mask). Why: the mirror's own defocus and spherical move
    # the local fringe frequency far from the 27 px carrier, and the sideband crop (at most half
    # the carrier frequency towards DC, where the background sits) still attenuates the
    # steepest, outer-zone phase. The bound allows that known bias (< 10 %) and nothing more.
    assert reference * 0.9 < spherical < reference * 1.02


@pytest.fixture(scope="module")
def circles():
    sets = (range(5, 11), range(11, 17), range(2282, 2288))
    return [wavefront_from_phase_shifts(read_frame_set([PSI / f"Image{i}.jpg" for i in r]), method="aia",
                                        aperture="circle") for r in sets]


def test_the_circle_choice_gives_the_three_sets_one_pupil_and_one_spherical(circles) -> None:
    """Fitted to the edge, the pupil is the same mirror circle in all three phase-shifted inputs.

    Radius: within 3 combined stated uncertainties plus 0.1 px (the camera may not have moved
    more than that). Z11 (each on its own circle): within 2 % of the two cycles' mean; the
    detected apertures' enclosing radii differ by 1.2 px (1.7 % in Z11 through the fourth
    power) and the circle removes that, leaving the difference between the measurements
    (measured: 0.4449, 0.4446 and 0.4484 waves, 0.8 % apart).
    """
    edges = [m.edge for m in circles]
    assert all(e is not None for e in edges) and all(m.aperture_choice == "circle" for m in circles)
    for a in edges[1:]:
        b = edges[0]
        assert abs(a.radius - b.radius) < 3 * np.hypot(a.sigma_radius, b.sigma_radius) + 0.1
    spherical = [_coefficients(m)[10] for m in circles]
    reference = np.mean(spherical[:2])
    assert all(s == pytest.approx(reference, rel=0.02) for s in spherical)


def test_the_carrier_frame_finds_the_same_mirror(circles) -> None:
    """The carrier frame's edge (in the local fringe variance) against the cycles' edge circle.

    Same mirror, camera and magnification. Centre: within 3 combined stated uncertainties (the
    carrier's ~1 px: its variance edge is rough, RMS 3.5 px about the circle). Radius: within
    3 %, a loose bound on purpose: the variance is half way at the edge only where the box holds
    whole fringes and the halo's mean intensity equals the disk's; here the halo ring around the
    rim is bright and the defocus leaves about one broad fringe per box at the left and right
    rims, and the circle comes out 6.6 px (2.3 %) wider than the cycles' (measured 291.1 against
    284.5 px). The carrier frame's pupil is therefore the weakest of the four; see results.md.
    """
    measured = wavefront_from_carrier(read_frame(PSI / "Image197.jpg"), sign=-1, aperture="circle")
    edge, reference = measured.edge, circles[0].edge
    assert edge is not None and reference is not None
    assert abs(edge.cx - reference.cx) < 3 * np.hypot(edge.sigma_cx, reference.sigma_cx)
    assert abs(edge.cy - reference.cy) < 3 * np.hypot(edge.sigma_cy, reference.sigma_cy)
    assert edge.radius == pytest.approx(reference.radius, rel=0.03)


def test_zygo_map_reads_and_its_low_order_terms_are_stable() -> None:
    data = read_metropro_dat(DATA / "zygo-dat" / "valid_zygo_dat_file.dat")
    assert data.phase_nm.shape == (432, 425)
    assert data.valid_count == 136359
    assert data.header.wavelength_nm == pytest.approx(632.8, rel=1e-6)
    mask = np.isfinite(data.phase_nm)
    circle = build_fitter(mask, method="circle", modes=36, dtype=np.float64)
    qr = build_fitter(mask, method="qr", modes=36, dtype=np.float64)
    c, q = circle.fit(data.phase_nm), qr.fit(data.phase_nm)
    # the same least-squares problem in two bases: identical circle coefficients
    np.testing.assert_allclose(q.circle_coefficients, c.coefficients, atol=1e-6)
    # Low orders and the number of modes: the circle basis is not orthogonal over this
    # aperture, so its defocus..spherical terms move when higher terms are added (measured: up
    # to 11 nm of 34 nm between 15 and 36 modes). The qr basis is orthonormalised in mode
    # order, so its first 15 coefficients cannot depend on the terms fitted after them.
    low = slice(3, 11)
    fewer_circle = build_fitter(mask, method="circle", modes=15, dtype=np.float64).fit(data.phase_nm)
    fewer_qr = build_fitter(mask, method="qr", modes=15, dtype=np.float64).fit(data.phase_nm)
    assert np.max(np.abs(fewer_circle.coefficients[low] - c.coefficients[low])) > 1.0
    np.testing.assert_allclose(fewer_qr.coefficients, q.coefficients[:15], atol=1e-6)
