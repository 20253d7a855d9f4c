"""The processors' aperture choices on synthetic interferograms with a known mirror edge."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from wavestack.pipeline.instrument import CLIPPED
from wavestack.pipeline import FitSettings, InterferometerOutcome, InterferometerSettings, measure_set

SHAPE = (240, 260)
FIT = FitSettings(method="circle", modes=15, dtype="float64")


def wavefront_from_phase_shifts(frames: NDArray, aperture: str | NDArray = "detected") -> InterferometerOutcome:
    """A phase-shifted set as analyze measures it (least squares, nominal steps)."""
    mask = None if isinstance(aperture, str) else aperture
    settings = InterferometerSettings(aperture=aperture if isinstance(aperture, str) else "detected", fit=FIT)
    return measure_set(list(frames), settings, mask=mask)


def wavefront_from_carrier(frame: NDArray, aperture: str = "detected") -> InterferometerOutcome:
    """One carrier frame as analyze measures it."""
    return measure_set([frame], InterferometerSettings(method="carrier", aperture=aperture, fit=FIT))
TRUE = (131.7, 118.2, 90.3)  # centre column, centre row, radius of the mirror: pixels


def _disk_fraction(sub: int = 8) -> NDArray[np.float64]:
    """Area fraction of each pixel inside the true circle (8 x 8 sub-pixels)."""
    cx, cy, r = TRUE
    offsets = (np.arange(sub) + 0.5) / sub - 0.5
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]].astype(np.float64)
    total = np.zeros(SHAPE)
    for dy in offsets:
        for dx in offsets:
            total += (cols + dx - cx) ** 2 + (rows + dy - cy) ** 2 < r * r
    return total / sub**2


def _phase_shifted_set(seed: int = 0) -> NDArray[np.float64]:
    """Six frames, 60 degree steps; a halo with its own (random-phase) modulation, bright on the left."""
    cx, cy, r = TRUE
    rng = np.random.default_rng(seed)
    disk = _disk_fraction()
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    rho2 = ((cols - cx) ** 2 + (rows - cy) ** 2) / r**2
    phi = 2.0 * np.pi * (0.8 * rho2 + 0.4 * (6 * rho2**2 - 6 * rho2 + 1))
    halo_b = np.where(cols < cx - 0.6 * r, 30.0, 6.0) * (1 + 0.3 * cv2.GaussianBlur(rng.standard_normal(SHAPE), (0, 0), 1.5))
    halo_phi = rng.uniform(0, 2 * np.pi, SHAPE)
    frames = []
    for k in range(6):
        delta = k * np.pi / 3
        fringe = 80.0 * disk * np.cos(phi + delta) + (1 - disk) * halo_b * np.cos(halo_phi + delta)
        frames.append(cv2.GaussianBlur(120.0 + fringe, (0, 0), 1.0) + rng.normal(0, 1.0, SHAPE))
    return np.stack(frames)


def test_phase_shifts_circle_choice_finds_the_true_edge() -> None:
    """The circle fitted to the modulation edge is the mirror's: 0.2 px (edge points are noisy at
    ~0.3 px each over ~570 rays, formal error ~0.03 px; the rest allows for the touching halo's
    grain); the aperture is the pixels inside it."""
    measured = wavefront_from_phase_shifts(_phase_shifted_set(), aperture="circle")
    edge = measured.edge
    cx, cy, r = TRUE
    assert measured.aperture_choice == "circle" and edge is not None
    assert math.hypot(edge.cx - cx, edge.cy - cy) < 0.2 and abs(edge.radius - r) < 0.2
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    inside = np.hypot(cols - edge.cx, rows - edge.cy) < edge.radius
    assert np.array_equal(measured.aperture.mask, inside)
    # the pixels left out are spikes of the rim, where the camera's blur mixes the halo's fringes into
    # the mirror's (the residual there is several times the interior's): none more than 3 px inside
    clipped = (measured.flags & CLIPPED) != 0
    assert measured.quality.excluded == measured.quality.clipped > 0
    assert (np.hypot(cols - cx, rows - cy)[clipped] > r - 3).all()
    assert np.isfinite(measured.waves[inside & ~clipped]).all() and np.isnan(measured.waves[~inside | clipped]).all()


def test_phase_shifts_detected_choice_stays_inside_the_mirror() -> None:
    """Default choice: no pixel more than 1 px beyond the true edge, none missing 1 px inside."""
    measured = wavefront_from_phase_shifts(_phase_shifted_set())
    cx, cy, r = TRUE
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    dist = np.hypot(cols - cx, rows - cy)
    assert measured.aperture_choice == "detected" and measured.edge is not None
    assert not (measured.aperture.mask & (dist > r + 1)).any()
    assert measured.aperture.mask[dist < r - 1].all()


def test_a_user_mask_is_analysed_as_given() -> None:
    frames = _phase_shifted_set()
    mask = np.zeros(SHAPE, dtype=bool)
    mask[60:180, 70:190] = True
    measured = wavefront_from_phase_shifts(frames, aperture=mask)
    assert measured.aperture_choice == "mask" and measured.edge is None
    assert np.array_equal(measured.aperture.mask, mask)
    with pytest.raises(ValueError, match="aperture mask has shape"):
        wavefront_from_phase_shifts(frames, aperture=mask[:-1])


def _carrier_frame(seed: int = 1) -> NDArray[np.float64]:
    """Carrier fringes (period 12 px) on the mirror; fringe-free speckle outside."""
    cx, cy, r = TRUE
    rng = np.random.default_rng(seed)
    disk = _disk_fraction()
    rows, cols = np.mgrid[: SHAPE[0], : SHAPE[1]]
    rho2 = ((cols - cx) ** 2 + (rows - cy) ** 2) / r**2
    phase = 2 * np.pi * cols / 12.0 + 2 * np.pi * 0.5 * rho2
    speckle = 20.0 * cv2.GaussianBlur(rng.standard_normal(SHAPE), (0, 0), 1.2)
    frame = 120.0 + disk * 80.0 * np.cos(phase) + (1 - disk) * speckle
    return cv2.GaussianBlur(frame, (0, 0), 0.8) + rng.normal(0, 1.0, SHAPE)


def test_carrier_aperture_edge_is_the_mirror_edge() -> None:
    """The carrier frame's aperture comes from the local fringe energy (the squared deviation
    from a two-period box mean, smoothed over a quarter period), whose half-way point is the edge
    (the contrast's is a quarter box outside it, which is why it used to be eroded by a period:
    12 px here, leaving the aperture ~6 px small).

    Near the rim the background box holds partial fringes, whose mean departs from the
    background and whose phase differs between the left and right rims (the carrier runs along
    the columns): measured, the circle's radius 0.37 px inside and its centre 0.31 px off along
    the carrier. Tolerances: 1.2 px inward, 2 px outward for the detected aperture's enclosing
    circle (it runs through the outermost pixel centres); the circle's centre to 0.5 px, its
    radius to 1.2 px.
    """
    cx, cy, r = TRUE
    detected = wavefront_from_carrier(_carrier_frame())
    ex, ey, er = detected.aperture.enclosing_circle()
    assert r - 1.2 < er < r + 2.0 and math.hypot(ex - cx, ey - cy) < 1.5
    edge = wavefront_from_carrier(_carrier_frame(), aperture="circle").edge
    assert edge is not None
    assert math.hypot(edge.cx - cx, edge.cy - cy) < 0.5 and abs(edge.radius - r) < 1.2
