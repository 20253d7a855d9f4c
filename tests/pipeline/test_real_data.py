"""Acceptance on real measured data (../shared/data): a 152.2 mm f/4 mirror and a Zygo map.

The mirror was tested at its centre of curvature (R = 1215 mm) at 654 nm without a null, so
the wavefront carries a large spherical term. Two 6-frame cycles (Image5-10, Image11-16) are
independent measurements; a tilted 6-frame set (Image2282-2287) and one carrier frame
(Image197) measure the same figure another way.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavestack.pipeline import Aperture, build_fitter
from wavestack.pipeline import ConicTest, implied_conic_constant
from wavestack.pipeline import read_frame, read_frame_set
from wavestack.pipeline import FitSettings, InterferometerOutcome, InterferometerSettings, measure_set
from wavestack.pipeline import read_metropro_dat

from shared_data import DATA, require_shared_data

PSI = DATA / "psi-mirror-654nm"
MIRROR = ConicTest(radius_of_curvature_mm=1215.0, diameter_mm=152.2, wavelength_nm=654.0)
MODES = 15

pytestmark = require_shared_data()


def _measured(frames, **settings) -> InterferometerOutcome:
    """One set through the processor every command runs (a stream of one set), circle fit in float64."""
    fit = FitSettings(method="circle", modes=MODES, remove=None, dtype="float64")
    return measure_set(list(frames), InterferometerSettings(fit=fit, **settings))


def _phase_shifted(frames, **settings) -> InterferometerOutcome:
    return _measured(frames, psi_algorithm="aia", **settings)


def _carrier(frame, **settings) -> InterferometerOutcome:
    return _measured([frame], method="carrier", carrier_sign=-1, **settings)


def _coefficients(measured: InterferometerOutcome) -> np.ndarray:
    """The measured map's circle coefficients over its whole aperture (pupil: the aperture's enclosing circle)."""
    fitter = build_fitter(measured.aperture, modes=MODES, dtype=np.float64)
    return fitter.fit(measured.waves, nan_policy="omit").coefficients


def _kasa(points: np.ndarray) -> tuple[float, float, float]:
    x, y = points[:, 0], points[:, 1]
    (d, e, f), *_ = np.linalg.lstsq(np.column_stack((x, y, np.ones_like(x))), -(x * x + y * y), rcond=None)
    return -d / 2, -e / 2, math.sqrt(d * d / 4 + e * e / 4 - f)


def amplitude_edge_circle(frame: np.ndarray, start: tuple[float, float, float], sectors: int = 24):
    """(col, row, radius, residual RMS) of the carrier frame's fringe-amplitude edge, from sectors.

    Nothing of the detector: the local fringe amplitude at radius r in a sector is the standard
    deviation of the frame's pixels in that sector's 1 px ring (an arc of ~75 px at the rim, ~3
    fringes: there is no background step inside a 1 px ring, and no box to spread the edge);
    per sector its disk level (median 10-40 px inside the current radius) and halo level (10-40
    px outside), the first fall below half way (linear interpolation), then a Kasa circle after
    dropping sectors more than 3 scaled MADs off; three rounds, each about the last circle.
    ``start`` is only the first round's centre and radius.
    """
    rows, cols = np.indices(frame.shape)
    cx, cy, r0 = start
    for _ in range(3):
        sector = np.floor((np.arctan2(rows - cy, cols - cx) + np.pi) / (2 * np.pi) * sectors).astype(int) % sectors
        key = (sector * 1000 + np.floor(np.hypot(cols - cx, rows - cy)).astype(int)).ravel()
        n, s1, s2 = (np.bincount(key, w, minlength=sectors * 1000).reshape(sectors, 1000)
                     for w in (None, frame.ravel(), (frame * frame).ravel()))
        with np.errstate(invalid="ignore", divide="ignore"):
            amp = np.where(n >= 20, np.sqrt(np.maximum(s2 / n - (s1 / n) ** 2, 0.0)), np.nan)
        points, lo = [], int(r0)
        for k in range(sectors):
            prof = amp[k]
            if np.all(np.isnan(prof[lo - 40:lo - 10])) or np.all(np.isnan(prof[lo + 10:lo + 40])):
                continue  # the halo (or the disk) is outside the frame in this sector
            level = 0.5 * (np.nanmedian(prof[lo - 40:lo - 10]) + np.nanmedian(prof[lo + 10:lo + 40]))
            fall = [q for q in range(lo - 20, lo + 40) if prof[q] >= level > prof[q + 1]]
            if fall:
                q = fall[0]
                dist = q + 0.5 + (prof[q] - level) / (prof[q] - prof[q + 1])
                angle = (k + 0.5) / sectors * 2 * np.pi - np.pi
                points.append((cx + dist * np.cos(angle), cy + dist * np.sin(angle)))
        pts = np.array(points)
        circle = _kasa(pts)
        for _ in range(5):
            res = np.hypot(pts[:, 0] - circle[0], pts[:, 1] - circle[1]) - circle[2]
            keep = np.abs(res - np.median(res)) <= 3 * 1.4826 * np.median(np.abs(res - np.median(res)))
            circle = _kasa(pts[keep])
        cx, cy, r0 = circle
    return cx, cy, r0, float(np.std(res[keep])), int(keep.sum())


@pytest.fixture(scope="module")
def cycles():
    first = read_frame_set([PSI / f"Image{i}.jpg" for i in range(5, 11)])
    second = read_frame_set([PSI / f"Image{i}.jpg" for i in range(11, 17)])
    return [_phase_shifted(frames) for frames in (first, second)]


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
    # Measured Z11 = 0.445 and 0.445 waves, K = -0.835 and -0.834 under our sign convention, on
    # the detected aperture (half-way edge, cut to its edge circle: pupil 284.5 px). With the
    # enclosing circle of the uncut detection (285.5 px): 0.451, K = -0.846; before the half-way
    # rule 0.470, K = -0.883, with a pupil 4 px too wide from a piece of halo at the left rim.
    assert abs(spherical[0] - spherical[1]) < 0.01
    assert abs(conics[0] - conics[1]) < 0.02
    assert all(s > 0.3 for s in spherical)  # a large spherical term, as the setup promises


def test_tilted_set_measures_the_same_spherical(cycles) -> None:
    tilted = read_frame_set([PSI / f"Image{i}.jpg" for i in range(2282, 2288)])
    measured = _phase_shifted(tilted)
    spherical = _coefficients(measured)[10]
    reference = np.mean([_coefficients(m)[10] for m in cycles])
    # Measured 0.447 against 0.445, now that each detected aperture is cut to its edge circle
    # (enclosing radius 284.6 and 284.5 px); 0.460 against 0.451 before, when the tilted set's rim
    # bulged at the upper right (286.7 vs 285.5 px) and Z11 scales with the pupil radius to the
    # fourth power. See the circle choice below.
    assert spherical == pytest.approx(reference, rel=0.05)


def test_carrier_frame_measures_the_spherical_on_the_same_pupil_as_the_cycles(cycles) -> None:
    frame = read_frame(PSI / "Image197.jpg")
    # One frame cannot tell phi from -phi; this setup's tilt needs sign -1 to match the
    # phase-shifted cycles (with +1 every coefficient flips sign).
    measured = _carrier(frame)
    assert measured.aperture.valid_count > 200_000  # the whole mirror, found from fringe variance
    # Compare like with like: Z11 scales with the pupil radius to the fourth power, and the
    # carrier aperture (from the fringe energy, cut to its edge circle: 284.6 px; it bites where the
    # fringes fade at the left rim, and the fit leaves out a rim band half a fringe period wide) is
    # not the cycles'. One fitter on the pixels all three share.
    common = measured.aperture.mask & cycles[0].aperture.mask & cycles[1].aperture.mask
    fitter = build_fitter(Aperture.from_mask(common), modes=MODES, dtype=np.float64)
    spherical = fitter.fit(measured.waves, nan_policy="omit").coefficients[10]
    reference = np.mean([fitter.fit(m.waves, nan_policy="omit").coefficients[10] for m in cycles])
    # Measured 0.435 against 0.446 (2.6 % low, the rim band left out; with the band fitted, 0.419
    # against 0.450, 7 % low; 0.431 against 0.449, 4 % low, on the common region
    # when the carrier aperture came from the box variance and took in halo rather than losing
    # the faded bites at the left rim; 0.432 against 0.461 with the eroded contrast mask before
    # the half-way edge). Why low: the mirror's own defocus and spherical move
    # the local fringe frequency far from the 27 px carrier, and the sideband crop (at most half
    # the carrier frequency towards DC, where the background sits) still attenuates the
    # steepest, outer-zone phase. The bound allows that known bias (< 10 %) and nothing more.
    assert reference * 0.9 < spherical < reference * 1.02


def test_the_carrier_frame_with_defaults_fits_on_the_mirrors_own_edge(cycles) -> None:
    """Analysed with the defaults, the carrier frame's pupil (its detected aperture's enclosing circle) is
    the mirror's edge, not a bump of halo where the rim meets the frame, and Z11 on that pupil agrees
    with the cycles' on theirs.

    Bounds: the enclosing radius within 1 px of the frame's own edge circle (its stated radius
    uncertainty is 0.4 px; measured 284.55 against 284.56 px, where the uncut outline's enclosing
    circle reached 295 px); Z11 within 5 % of the two cycles' mean (Z11 scales with the pupil
    radius to the fourth power: 3.7 % for 295 against 284.5 px, 10 % with the spherical's carrier
    bias of the common-region test above; measured 0.435 against 0.445).
    """
    measured = _carrier(read_frame(PSI / "Image197.jpg"))
    _, _, radius = measured.aperture.enclosing_circle()
    assert measured.edge is not None
    assert abs(radius - measured.edge.radius) < 1.0
    spherical = _coefficients(measured)[10]
    reference = np.mean([_coefficients(m)[10] for m in cycles])
    assert spherical == pytest.approx(reference, rel=0.05)


@pytest.fixture(scope="module")
def circles():
    sets = (range(5, 11), range(11, 17), range(2282, 2288))
    return [_phase_shifted(read_frame_set([PSI / f"Image{i}.jpg" for i in r]), aperture="circle") for r in sets]


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


@pytest.fixture(scope="module")
def carrier_edge():
    """The carrier frame and its amplitude edge (col, row, radius, residual RMS, sectors kept)."""
    frame = read_frame(PSI / "Image197.jpg")
    rows, cols = frame.shape
    return frame, amplitude_edge_circle(frame.astype(np.float64), (cols / 2, rows / 2, 0.45 * rows))


def test_the_carrier_frame_finds_the_mirror_edge_of_its_fringe_amplitude(carrier_edge) -> None:
    """The carrier frame's edge circle against the amplitude edge computed here from the frame.

    Tolerances: 3 combined standard uncertainties (the circle's stated ones; the estimate's
    from its residual RMS over its sectors, ``rms / sqrt(n)`` in radius, ``rms sqrt(2 / n)`` in
    centre) plus 0.5 px for what the two definitions may differ by (a half-way level of the
    smoothed fringe energy against one of the ring amplitude, across an edge blurred by the
    camera by ~1-2 px). Measured: 284.6 +- 0.4 px around (391.7, 299.1) against 284.4 px around
    (392.1, 298.5) (RMS 0.56 px over 21 sectors). Before the fringe energy, from the box
    variance: 291.1 +- 0.7 px, 6.7 px wide, from the background step and the halo's speckle
    that a 55 px box spreads across the edge.
    """
    frame, (ex, ey, er, rms, n) = carrier_edge
    edge = _carrier(frame, aperture="circle").edge
    assert edge is not None
    tol_r = 3 * math.hypot(edge.sigma_radius, rms / math.sqrt(n)) + 0.5
    tol_c = 3 * math.hypot(math.hypot(edge.sigma_cx, edge.sigma_cy), rms * math.sqrt(2 / n)) + 0.5
    assert abs(edge.radius - er) < tol_r
    assert math.hypot(edge.cx - ex, edge.cy - ey) < tol_c


def test_the_carrier_frames_detected_aperture_takes_in_no_halo(carrier_edge) -> None:
    """Pixels of the detected aperture more than 3 px outside the amplitude edge circle.

    Bound: under 1 % of the aperture. 3 px: the detected rim follows the fringe energy's own
    rim, rough by ~3.5 px RMS about its circle; 1 %: a few such bumps where the edge meets
    the frame's top and bottom (measured 0.3 %). Before the fringe energy the box variance's
    aperture took in 3.3 %: halo strips at the top and bottom of the frame (enclosing radius
    302.5 px against this edge's 284.4).
    """
    frame, (ex, ey, er, _, _) = carrier_edge
    mask = _carrier(frame).aperture.mask
    rows, cols = np.indices(mask.shape)
    outside = mask & (np.hypot(cols - ex, rows - ey) > er + 3.0)
    assert outside.sum() < 0.01 * mask.sum()


def test_the_carrier_frame_finds_the_same_mirror(circles) -> None:
    """The carrier frame's edge circle against the cycles' edge circle: the same mirror.

    Same mirror, camera and magnification. Centre and radius: within 3 combined stated
    uncertainties plus 0.5 px (the carrier frame was taken at another time: the camera or
    mirror may have moved by a fraction of a pixel). Measured: 284.6 +- 0.4 px against 284.5.
    Before the fringe energy the box variance put it at 291.1 +- 0.7 px, 2.3 % wider.
    """
    measured = _carrier(read_frame(PSI / "Image197.jpg"), aperture="circle")
    edge, reference = measured.edge, circles[0].edge
    assert edge is not None and reference is not None
    assert abs(edge.cx - reference.cx) < 3 * np.hypot(edge.sigma_cx, reference.sigma_cx) + 0.5
    assert abs(edge.cy - reference.cy) < 3 * np.hypot(edge.sigma_cy, reference.sigma_cy) + 0.5
    assert abs(edge.radius - reference.radius) < 3 * np.hypot(edge.sigma_radius, reference.sigma_radius) + 0.5


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
