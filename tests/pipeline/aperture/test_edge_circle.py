"""The half-way edge and the aperture choices on synthetic maps with a known edge.

Maps are rendered from a known circle by area sampling (8 x 8 sub-pixels per pixel), blurred by
a Gaussian edge response and given noise, so the true edge is known to far better than the
tolerances below.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from wavestack.pipeline.aperture import (
    DetectionSettings,
    EdgeFitError,
    Topology,
    choose_aperture,
    detect_aperture,
    fit_circle,
    fit_edge_circle,
    modulation_levels,
)

SHAPE = (300, 320)
TRUE = (161.3, 148.6, 110.4)  # centre column, centre row, radius: pixels
DISK, HALO, TOUCHING = 80.0, 8.0, 38.0  # levels: the disk, the halo, the halo touching the rim


def _area_fraction(inside, shape: tuple[int, int] = SHAPE, sub: int = 8) -> NDArray[np.float64]:
    """Fraction of each pixel's area where ``inside(x, y)`` holds (x = column, y = row)."""
    offsets = (np.arange(sub) + 0.5) / sub - 0.5
    rows, cols = np.mgrid[: shape[0], : shape[1]].astype(np.float64)
    total = np.zeros(shape)
    for dy in offsets:
        for dx in offsets:
            total += inside(cols + dx, rows + dy)
    return total / sub**2


def _disk_with_one_sided_halo(seed: int = 0, blur_px: float = 1.2) -> NDArray[np.float64]:
    """Disk, dim halo, and on the left a bright speckled halo touching the rim over ~100 degrees."""
    cx, cy, r = TRUE
    disk = _area_fraction(lambda x, y: (x - cx) ** 2 + (y - cy) ** 2 < r * r)
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    rng = np.random.default_rng(seed)
    speckle = cv2.GaussianBlur(rng.standard_normal(SHAPE), (0, 0), 1.5) * 25.0
    left = (cols < cx - 0.65 * r) & (np.hypot(cols - cx, rows - cy) < r + 40)
    halo = np.where(left, TOUCHING + speckle, HALO)
    signal = DISK * disk + halo * (1.0 - disk)
    signal = cv2.GaussianBlur(signal, (0, 0), blur_px) + rng.normal(0.0, 2.0, SHAPE)
    return np.clip(signal, 0.0, None)


def test_the_edge_circle_of_a_disk_with_a_one_sided_halo_is_the_true_circle() -> None:
    """Sub-pixel centre and radius although a bright halo touches a third of the rim.

    Tolerance 0.15 px: ~690 edge points with ~0.3 px noise each give a formal error of ~0.02 px;
    the rest allows for the edge response's residual bias where the touching halo varies along
    the ray (its speckle has a 1.5 px grain), which the per-ray levels only average. The stated
    uncertainty must cover the true error (3 sigma plus 0.05 px).
    """
    signal = _disk_with_one_sided_halo()
    detected = detect_aperture(signal)
    edge = fit_edge_circle(signal, detected)
    cx, cy, r = TRUE
    error_c, error_r = math.hypot(edge.cx - cx, edge.cy - cy), abs(edge.radius - r)
    assert error_c < 0.15 and error_r < 0.15
    assert error_c < 3 * math.hypot(edge.sigma_cx, edge.sigma_cy) + 0.05
    assert error_r < 3 * edge.sigma_radius + 0.05


def test_the_detected_aperture_stops_at_the_edge_where_the_halo_touches() -> None:
    """The pixel mask: no piece of the touching halo, and the half-way threshold.

    Pixels whose centres are more than 1 px outside the true circle (the blur and noise move a
    pixel's decision by well under a pixel at the edge) must not be in the aperture; Otsu's rule
    on the same map takes in pieces of the bright halo (that is the fault this rule fixes).
    """
    signal = _disk_with_one_sided_halo()
    cx, cy, r = TRUE
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    outside = np.hypot(cols - cx, rows - cy) > r + 1.0
    inside = np.hypot(cols - cx, rows - cy) < r - 1.0
    detected = detect_aperture(signal)
    assert not (detected.aperture.mask & outside).any()
    assert detected.aperture.mask[inside].all()
    levels = detected.levels
    assert levels is not None
    # the robust levels come back to within the noise and the halo's share of the band
    assert abs(levels.disk - DISK) < 2.0 and HALO - 2.0 < levels.halo < TOUCHING
    assert detected.threshold == pytest.approx(levels.midpoint)
    otsu = detect_aperture(signal, DetectionSettings(rule="otsu"))
    assert (otsu.aperture.mask & outside).any()


def test_levels_are_medians_inside_and_outside_a_coarse_mask() -> None:
    """The disk and halo levels of a two-level map are its two levels, whatever the areas."""
    rows, cols = np.mgrid[:100, :100]
    coarse = (np.hypot(cols - 50, rows - 50) < 30).astype(np.uint8)
    values = np.where(coarse, 70.0, 5.0)
    values[45:55, 45:55] = 0.0  # a dropout inside (100 px of ~2800): the median ignores it
    levels = modulation_levels(values, coarse)
    assert (levels.disk, levels.halo, levels.midpoint) == (70.0, 5.0, 37.5)


def test_fit_circle_rejects_outliers_and_its_uncertainty_matches_the_scatter() -> None:
    """Geometric fit with rejection; the stated sigma of the radius against Monte Carlo.

    With independent Gaussian noise s on n points round a full circle, the radius' standard
    error is s / sqrt(n) and each centre coordinate's s sqrt(2 / n). Checked against the
    spread of 200 fits (30 % allowance: 200 samples estimate a standard deviation to ~5 %).
    """
    rng = np.random.default_rng(3)
    n, s = 400, 0.3
    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    radii, stated = [], []
    for _ in range(200):
        noisy = 50.0 + rng.normal(0.0, s, n)
        noisy[::40] += 5.0  # 10 outliers, 5 px out
        pts = np.column_stack((10 + noisy * np.cos(theta), -4 + noisy * np.sin(theta)))
        circle = fit_circle(pts)
        assert circle.rejected >= 10
        radii.append(circle.radius)
        stated.append(circle.sigma_radius)
    assert np.std(radii) == pytest.approx(s / math.sqrt(n), rel=0.3)
    assert np.median(stated) == pytest.approx(np.std(radii), rel=0.3)
    assert np.mean(radii) == pytest.approx(50.0, abs=4 * s / math.sqrt(n * 200))


def test_fit_circle_needs_points() -> None:
    with pytest.raises(EdgeFitError, match="at least 8"):
        fit_circle(np.zeros((5, 2)))


def test_a_long_thin_aperture_is_still_detected() -> None:
    """A 260 x 34 px strip (the shape the mapped fit exists for): the detected choice keeps it.

    The circle choice refuses it or, if rays happen to find a circle, the detected choice is
    unaffected: the detected aperture is the strip to within the blurred rim (1 px).
    """
    strip = _area_fraction(lambda x, y: (np.abs(x - 160.2) < 130.0) & (np.abs(y - 150.4) < 17.0))
    rng = np.random.default_rng(4)
    signal = cv2.GaussianBlur(10.0 + 70.0 * strip, (0, 0), 1.2) + rng.normal(0.0, 2.0, SHAPE)
    chosen = choose_aperture(signal, "detected")
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    core = (np.abs(cols - 160.2) < 129.0) & (np.abs(rows - 150.4) < 16.0)
    beyond = (np.abs(cols - 160.2) > 131.0) | (np.abs(rows - 150.4) > 18.0)
    assert chosen.choice == "detected"
    assert chosen.aperture.mask[core].all() and not (chosen.aperture.mask & beyond).any()
    assert chosen.aperture.topology is Topology.SIMPLY_CONNECTED


def test_an_off_centre_obscuration_stays_a_hole_in_both_choices() -> None:
    """A disk with an off-centre obscuration: detected keeps the hole, and so does the circle."""
    cx, cy, r = TRUE
    pupil = _area_fraction(lambda x, y: ((x - cx) ** 2 + (y - cy) ** 2 < r * r)
                           & ((x - cx - 40) ** 2 + (y - cy + 20) ** 2 > 25.0**2))
    rng = np.random.default_rng(5)
    signal = cv2.GaussianBlur(10.0 + 70.0 * pupil, (0, 0), 1.2) + rng.normal(0.0, 2.0, SHAPE)
    for choice in ("detected", "circle"):
        chosen = choose_aperture(signal, choice)
        assert chosen.aperture.topology is Topology.DOUBLY_CONNECTED
        assert not chosen.aperture.mask[round(cy - 20), round(cx + 40)]
    edge = choose_aperture(signal, "circle").edge
    assert edge is not None
    # the outer edge only: rays stop at the obscuration's edge where they cross it (rejected)
    assert math.hypot(edge.cx - cx, edge.cy - cy) < 0.2 and abs(edge.radius - r) < 0.2


def test_a_user_mask_is_used_as_given_and_its_shape_checked() -> None:
    signal = _disk_with_one_sided_halo()
    mask = np.zeros(SHAPE, dtype=bool)
    mask[100:200, 100:220] = True
    chosen = choose_aperture(signal, mask)
    assert chosen.choice == "mask" and chosen.edge is None and chosen.detected is None
    assert np.array_equal(chosen.aperture.mask, mask)
    with pytest.raises(ValueError, match=r"aperture mask has shape \(10, 10\); expected the map's shape"):
        choose_aperture(signal, np.ones((10, 10), dtype=bool))
    with pytest.raises(ValueError, match="aperture choice is 'square'"):
        choose_aperture(signal, "square")


def test_settings_check_the_new_fields() -> None:
    with pytest.raises(ValueError, match="rule"):
        DetectionSettings(rule="median")
    with pytest.raises(ValueError, match="smooth_sigma_px"):
        DetectionSettings(smooth_sigma_px=-1.0)
