"""Tests for wavestack.pipeline.aperture.detect: aperture detection, IoU, aperture tracking.

Synthetic maps check each step (threshold, speckle removal, dropout filling, obscurations,
component selection); the real phase-shifting frames in the shared data check that the mirror,
not its speckled halo, is found.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from wavestack.pipeline.aperture.region import Aperture, EmptyAperture, Topology
from wavestack.pipeline.aperture.compare import ApertureTracker, aperture_iou
from wavestack.pipeline.aperture.detect import DetectionSettings, detect_aperture

from shared_data import DATA, require_shared_data

_DATA = DATA / "psi-mirror-654nm"


# ----------------------------------------------------------------------------- helpers


def _disk(shape: tuple[int, int], row: float, col: float, radius: float) -> NDArray[np.bool_]:
    """Pixels whose centre lies within ``radius`` of (row, col)."""
    rows, cols = np.mgrid[: shape[0], : shape[1]]
    return (rows - row) ** 2 + (cols - col) ** 2 <= radius**2


def _differs_on_rim(mask: NDArray[np.bool_], expected: NDArray[np.bool_]) -> int:
    """Number of pixels where ``mask`` and ``expected`` differ; fails if any is off the rim.

    The opening removes the one-pixel tips of a digital disk at its four axis extremes
    (OpenCV's 5 x 5 elliptical kernel does not fit there), so exact equality is too strict.
    """
    kernel = np.ones((3, 3), np.uint8)
    as_u8 = expected.astype(np.uint8)
    rim = cv2.dilate(as_u8, kernel) != cv2.erode(as_u8, kernel)
    differ = mask != expected
    assert not (differ & ~rim).any(), "masks differ away from the rim"
    return int(np.count_nonzero(differ))


def _lens_iou(radius: float, distance: float) -> float:
    """IoU of two disks of equal ``radius`` whose centres are ``distance`` apart."""
    lens = 2 * radius**2 * math.acos(distance / (2 * radius)) - 0.5 * distance * math.sqrt(
        4 * radius**2 - distance**2
    )
    return lens / (2 * math.pi * radius**2 - lens)


def _modulation(first: int) -> NDArray[np.float64]:
    """Modulation B = (2/N) |sum_k I_k exp(-i k 2 pi/6)| of frames Image<first>..+5."""
    frames = []
    for k in range(6):
        path = _DATA / f"Image{first + k}.jpg"
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        assert image is not None, f"cannot read {path}"
        frames.append(image.astype(np.float64))
    weights = np.exp(-1j * 2 * np.pi * np.arange(6) / 6)
    return 2.0 / 6.0 * np.abs(np.tensordot(weights, np.stack(frames), axes=1))


def _half_max_circle(signal_map: NDArray[np.float64], cx: float, cy: float) -> tuple[float, ...]:
    """Mirror circle from half-maximum edges of 21-px bands through (cx, cy), detector-free.

    Returns (centre col, centre row, mean radius) in pixels.
    """
    row, col = round(cy), round(cx)
    across = signal_map[row - 10 : row + 11].mean(axis=0)
    down = signal_map[:, col - 10 : col + 11].mean(axis=1)
    edges = []
    for profile, centre in ((across, col), (down, row)):
        above = np.flatnonzero(profile > 0.5 * np.median(profile[centre - 100 : centre + 100]))
        edges.append((above[0], above[-1]))
    (left, right), (top, bottom) = edges
    return (left + right) / 2, (top + bottom) / 2, (right - left + bottom - top) / 4


@pytest.fixture(scope="module")
def cycle_map() -> NDArray[np.float64]:
    return _modulation(5)


@pytest.fixture(scope="module")
def tilted_map() -> NDArray[np.float64]:
    return _modulation(2282)


# ----------------------------------------------------------------------------- settings


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("threshold", math.nan),
        ("threshold", "0.5"),
        ("threshold", True),
        ("open_radius_px", -1),
        ("open_radius_px", 1.5),
        ("close_radius_px", True),
        ("fill_dropouts_below_px", -5),
        ("keep", "biggest"),
        ("min_component_px", 0),
    ],
)
def test_settings_reject_bad_fields(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        DetectionSettings(**{field: value})


def test_settings_are_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        DetectionSettings().keep = "all"  # type: ignore[misc]


# ----------------------------------------------------------------------------- synthetic maps


def test_disk_with_speckle_dropouts_and_obscuration() -> None:
    """Speckle and halo blobs go, small dropouts are filled, the obscuration stays."""
    rng = np.random.default_rng(1)
    shape = (400, 400)
    annulus = _disk(shape, 200, 200, 150) & ~_disk(shape, 200, 200, 30)
    signal = annulus + 0.05 * rng.standard_normal(shape)
    signal[(rng.random(shape) < 0.03) & ~_disk(shape, 200, 200, 155)] = 1.0  # speckle
    blobs = [(15, 15), (15, 370), (380, 20), (375, 375)]
    for row, col in blobs:  # 6 x 6 halo pieces: survive the opening, below 500 px
        signal[row : row + 6, col : col + 6] = 1.0
    dropouts = [(200, 100), (100, 200), (290, 200), (200, 300), (140, 140)]
    for row, col in dropouts:  # ~50 px dark spots: too wide for the closing, below 200 px
        signal[_disk(shape, row, col, 4)] = 0.0
    signal[120, 220] = signal[260, 180] = np.nan  # single-pixel NaN dropouts (closed)

    result = detect_aperture(signal)

    aperture = result.aperture
    assert aperture.topology is Topology.DOUBLY_CONNECTED
    assert aperture.components == 1
    assert result.filled_dropouts == len(dropouts)
    assert result.removed_components == len(blobs)
    assert 0.1 < result.threshold < 0.9
    assert aperture_iou(aperture, annulus) > 0.99
    assert all(aperture.mask[row, col] for row, col in dropouts)
    assert not aperture.mask[200, 200]  # the obscuration


def test_large_fill_limit_fills_the_obscuration() -> None:
    shape = (200, 200)
    annulus = _disk(shape, 100, 100, 80) & ~_disk(shape, 100, 100, 10)  # hole of ~317 px
    kept = detect_aperture(annulus.astype(float))
    filled = detect_aperture(annulus.astype(float), DetectionSettings(fill_dropouts_below_px=400))
    assert (kept.aperture.topology, kept.filled_dropouts) == (Topology.DOUBLY_CONNECTED, 0)
    assert (filled.aperture.topology, filled.filled_dropouts) == (Topology.SIMPLY_CONNECTED, 1)


def test_keep_all_and_keep_largest() -> None:
    shape = (200, 300)
    big, small = _disk(shape, 100, 80, 60), _disk(shape, 100, 230, 40)
    speck = np.zeros(shape, dtype=bool)
    speck[10:20, 140:150] = True  # 100 px: below min_component_px
    signal = (big | small | speck).astype(np.float32)

    both = detect_aperture(signal, DetectionSettings(keep="all"))
    largest = detect_aperture(signal)

    assert (both.aperture.components, both.removed_components) == (2, 1)
    assert both.aperture.topology is Topology.UNSUPPORTED
    assert _differs_on_rim(both.aperture.mask, big | small) <= 8
    assert (largest.aperture.components, largest.removed_components) == (1, 2)
    assert _differs_on_rim(largest.aperture.mask, big) <= 4


def test_explicit_threshold_separates_disk_from_halo() -> None:
    """Three levels: Otsu (the rule asked for by name) puts the halo with the disk, an explicit 0.8 does not."""
    shape = (240, 240)
    disk = _disk(shape, 120, 120, 70)
    halo = _disk(shape, 120, 120, 100) & ~disk
    signal = 1.0 * disk + 0.6 * halo

    otsu = detect_aperture(signal, DetectionSettings(rule="otsu"))
    explicit = detect_aperture(signal, DetectionSettings(threshold=0.8))

    assert otsu.threshold < 0.6
    assert _differs_on_rim(otsu.aperture.mask, disk | halo) <= 4
    assert explicit.threshold == 0.8
    assert _differs_on_rim(explicit.aperture.mask, disk) <= 4
    with pytest.raises(EmptyAperture):
        detect_aperture(signal, DetectionSettings(threshold=1.0))


def test_reported_threshold_is_the_one_applied() -> None:
    """Otsu's rule without morphology or selection: the mask is exactly map > threshold (NaN invalid)."""
    rng = np.random.default_rng(2)
    signal = rng.normal(10.0, 1.0, (64, 64))
    signal[:, 32:] += 5.0
    signal[5, 40] = np.nan
    raw = DetectionSettings(
        open_radius_px=0, close_radius_px=0, fill_dropouts_below_px=0, keep="all",
        min_component_px=1, rule="otsu",
    )
    result = detect_aperture(signal, raw)
    with np.errstate(invalid="ignore"):
        expected = signal > result.threshold
    assert 11.0 < result.threshold < 14.0
    # The documented rescaling: Otsu on round(255 (v - lo) / (hi - lo)), boundary t + 0.5.
    finite = signal[np.isfinite(signal)]
    lo, hi = finite.min(), finite.max()
    eight_bit = np.round(255 * (finite - lo) / (hi - lo)).astype(np.uint8).reshape(1, -1)
    level, _ = cv2.threshold(eight_bit, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    assert result.threshold == pytest.approx(lo + (level + 0.5) * (hi - lo) / 255, rel=1e-12)
    assert np.array_equal(result.aperture.mask, expected)
    assert not result.aperture.mask[5, 40]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int64, np.float32, np.bool_])
def test_integer_float_and_bool_maps(dtype: type) -> None:
    disk = _disk((120, 120), 60, 60, 40)
    result = detect_aperture((disk * 200).astype(dtype))
    assert _differs_on_rim(result.aperture.mask, disk) <= 8


def test_nan_surround_is_invalid() -> None:
    disk = _disk((100, 100), 50, 50, 30)
    signal = np.where(disk, 3.0, np.nan)
    signal[~disk & _disk((100, 100), 50, 50, 40)] = 1.0
    result = detect_aperture(signal)
    assert _differs_on_rim(result.aperture.mask, disk) <= 8


@pytest.mark.parametrize(
    ("signal", "settings"),
    [
        (np.full((50, 50), np.nan), DetectionSettings()),
        (np.full((50, 50), np.nan), DetectionSettings(threshold=0.0)),
        (np.full((50, 50), 2.0), DetectionSettings()),  # constant: Otsu undefined
        (np.zeros((50, 50)), DetectionSettings(threshold=0.5)),
        (_disk((50, 50), 25, 25, 5).astype(float), DetectionSettings()),  # 81 px < 500
    ],
)
def test_empty_results_raise(signal: NDArray[np.float64], settings: DetectionSettings) -> None:
    with pytest.raises(EmptyAperture):
        detect_aperture(signal, settings)


@pytest.mark.parametrize(
    ("signal", "match"),
    [
        (np.zeros((4, 4, 3)), "signal_map"),
        (np.zeros((0, 5)), "signal_map"),
        (np.array([["a", "b"]]), "signal_map"),
        (np.zeros((4, 4), dtype=complex), "signal_map"),
        (np.array([[1.0, np.inf], [0.0, 1.0]]), "signal_map"),
    ],
)
def test_bad_maps_raise_value_error(signal: NDArray[np.generic], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        detect_aperture(signal)


def test_bad_arguments_raise_value_error() -> None:
    with pytest.raises(ValueError, match="settings"):
        detect_aperture(np.ones((8, 8)), {"keep": "all"})  # type: ignore[arg-type]
    for bad in (-1.0, math.inf, math.nan, "4"):
        with pytest.raises(ValueError, match="min_hole_area_px"):
            detect_aperture(np.full((8, 8), np.nan), min_hole_area_px=bad)  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- IoU


def test_iou_identical_disjoint_and_shifted() -> None:
    shape = (300, 300)
    disk = _disk(shape, 150, 150, 100)
    assert aperture_iou(disk, disk) == 1.0
    assert aperture_iou(Aperture.from_mask(disk), disk) == 1.0
    assert aperture_iou(_disk(shape, 60, 60, 40), _disk(shape, 200, 200, 40)) == 0.0
    for shift in (3.0, 30.0, 2.5):
        measured = aperture_iou(disk, _disk(shape, 150, 150 + shift, 100))
        assert measured == pytest.approx(_lens_iou(100.0, shift), rel=0.01)


def test_iou_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="shape"):
        aperture_iou(np.ones((4, 4)), np.ones((4, 5)))
    with pytest.raises(ValueError, match="empty"):
        aperture_iou(np.zeros((4, 4)), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="b"):
        aperture_iou(np.ones((4, 4)), np.ones(4))


# ----------------------------------------------------------------------------- tracker


@pytest.mark.parametrize("radius", [50, 100])  # 3-px shift: IoU 0.926 and 0.963
def test_tracker_first_same_and_shifted(radius: int) -> None:
    shape = (260, 260)
    disk = Aperture.from_mask(_disk(shape, 130, 130, radius))
    shifted = Aperture.from_mask(_disk(shape, 130, 133, radius))
    iou = aperture_iou(disk, shifted)
    assert iou == pytest.approx(_lens_iou(radius, 3.0), rel=0.01)  # below the default 0.98

    tracker = ApertureTracker()
    first = tracker.update(disk)
    assert first.changed and tracker.reference is disk
    same = tracker.update(disk)
    assert (same.changed, same.iou) == (False, 1.0)
    assert iou < 0.98 and tracker.update(shifted).changed

    for threshold, expected in ((iou - 0.005, False), (iou + 0.005, True)):
        tracker = ApertureTracker(threshold)
        tracker.update(disk)
        change = tracker.update(shifted)
        assert (change.changed, change.iou) == (expected, pytest.approx(iou))


def test_tracker_compares_with_reference_so_drift_accumulates() -> None:
    shape = (260, 260)
    tracker = ApertureTracker(0.97)  # between the 2-px (0.975) and 3-px (0.963) IoU
    tracker.update(Aperture.from_mask(_disk(shape, 130, 120, 100)))
    verdicts = [
        tracker.update(Aperture.from_mask(_disk(shape, 130, 120 + shift, 100))).changed
        for shift in (1, 2, 3, 4)
    ]
    assert verdicts == [False, False, True, False]  # 3 px from the reference; then 1 px


def test_tracker_topology_and_shape_changes() -> None:
    shape = (200, 200)
    disk = _disk(shape, 100, 100, 80)
    tracker = ApertureTracker(0.9)
    tracker.update(Aperture.from_mask(disk))
    change = tracker.update(Aperture.from_mask(disk & ~_disk(shape, 100, 100, 8)))
    assert change.changed and change.iou > 0.9 and "topology" in change.reason
    change = tracker.update(Aperture.from_mask(_disk((200, 210), 100, 100, 80)))
    assert change.changed and "shape" in change.reason
    tracker.reset()
    assert tracker.reference is None


@pytest.mark.parametrize("threshold", [0.0, 1.5, math.nan, True])
def test_tracker_rejects_bad_threshold(threshold: float) -> None:
    with pytest.raises(ValueError, match="iou_threshold"):
        ApertureTracker(threshold)


def test_tracker_rejects_non_aperture() -> None:
    with pytest.raises(ValueError, match="aperture"):
        ApertureTracker().update(np.ones((4, 4)))  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- real data


@require_shared_data()
def test_real_cycle_finds_the_mirror_not_the_halo(cycle_map: NDArray[np.float64]) -> None:
    """Image5..10: one disk of radius ~285 px with its central speck; the halo is excluded.

    Measured with the half-way rule: disk level 75.7, halo 10.0, threshold 42.9; minimum
    enclosing circle (392.1, 299.2), radius 285.6 px (Otsu's rule: threshold 41.8 and a 6 x 6 px
    halo blob glued to the left rim by the closing, circle (388.5, 299.6), 288.5 px); half-maximum
    edges of the bands give (392, 299.5), 283.75 px. The dark central speck at (303, 391) is
    206 px at the half-way level, above the 200-px fill limit, so it stays as a hole (it was
    192 px under Otsu's lower threshold and was filled).
    """
    result = detect_aperture(cycle_map)
    aperture = result.aperture
    cx, cy, r = aperture.enclosing_circle()
    edge_cx, edge_cy, edge_r = _half_max_circle(cycle_map, cx, cy)

    assert aperture.components == 1
    # Range: the half-maximum radius of the bands (whole pixels, rounded in) minus 1 px, plus
    # up to 3 px for the rim's own departures from a circle, which the enclosing circle takes.
    assert edge_r - 1 <= r <= edge_r + 3 and 275 <= r <= 295
    assert math.hypot(cx - edge_cx, cy - edge_cy) <= 2
    assert math.hypot(cx - 400, cy - 300) <= 15
    # The dark central speck is below the threshold, and at this threshold larger than the
    # fill limit: a hole, not filled.
    assert cycle_map[303, 391] < result.threshold and not aperture.mask[303, 391]
    assert aperture.topology is Topology.DOUBLY_CONNECTED
    # The halo ring has pixels above the threshold, yet none is in the aperture.
    rows, cols = np.mgrid[: cycle_map.shape[0], : cycle_map.shape[1]]
    ring = (np.hypot(cols - cx, rows - cy) >= 300) & (np.hypot(cols - cx, rows - cy) <= 380)
    assert np.count_nonzero(cycle_map[ring] > result.threshold) > 0
    assert not aperture.mask[ring].any()


@require_shared_data()
def test_real_tilted_set_gives_the_same_circle(
    cycle_map: NDArray[np.float64], tilted_map: NDArray[np.float64]
) -> None:
    """Image2282..2287: same mirror circle within a few pixels.

    Measured (half-way rule): threshold 29.4, enclosing circle (393.5, 300.7), radius 287.0 px
    (cycle set: (392.1, 299.2), 285.6 px); 40 dropouts filled, 1 halo component removed. A
    low-modulation blemish at (351, 614) (row, col) is above the 200-px fill limit and stays
    as a hole, so this set is doubly connected with the default settings.
    """
    reference = detect_aperture(cycle_map).aperture.enclosing_circle()
    result = detect_aperture(tilted_map)
    cx, cy, r = result.aperture.enclosing_circle()

    assert math.hypot(cx - reference[0], cy - reference[1]) <= 6
    assert abs(r - reference[2]) <= 3
    assert result.aperture.components == 1
    assert result.aperture.topology is Topology.DOUBLY_CONNECTED
    assert not result.aperture.mask[351, 614]
    relaxed = detect_aperture(tilted_map, DetectionSettings(fill_dropouts_below_px=400))
    assert relaxed.aperture.topology is Topology.SIMPLY_CONNECTED


# ----------------------------------------------------------------------------- a large map


def test_detection_at_1024_closes_specks_and_fills_dropouts() -> None:
    """A 1024^2 map with a speckled halo, pinholes and 49-px dropouts: one simply connected aperture.

    Its speed is measured by ``benchmarks/bench_signal.py``, never here: timed tests on a shared
    machine fail for reasons that are not the code's.
    """
    rng = np.random.default_rng(3)
    n = 1024
    rows, cols = np.mgrid[:n, :n]
    radius = np.hypot(rows - 511.5, cols - 511.5)
    signal = (radius < 400) + np.where(
        (radius >= 400) & (radius < 500), 0.5 * rng.random((n, n)) ** 2, 0.0
    )
    signal += 0.05 * rng.standard_normal((n, n))
    signal[(radius < 400) & (rng.random((n, n)) < 0.002)] = 0.0  # closed by the closing
    for row, col in rng.uniform(250, 770, (20, 2)):  # 49-px dropouts: filled
        signal[np.hypot(rows - row, cols - col) <= 4] = 0.0

    result = detect_aperture(signal)
    assert result.aperture.topology is Topology.SIMPLY_CONNECTED
    assert result.filled_dropouts == 20
    # the half-way edge of a unit step at r = 400 beside a halo of mean ~0.17: within a pixel of 400
    assert abs(np.sqrt(result.aperture.valid_count / np.pi) - 400.0) < 1.0
