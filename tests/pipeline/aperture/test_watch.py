"""The cheap per-frame aperture check agrees with full detection on still and changed apertures."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.aperture.detect import detect_aperture
from wavestack.pipeline.aperture.watch import ApertureWatch


def _disk_modulation(shape: tuple[int, int], centre: tuple[float, float], radius: float,
                     rng: np.random.Generator, obscuration: float = 0.0) -> np.ndarray:
    rows, cols = np.indices(shape)
    r = np.hypot(cols - centre[0], rows - centre[1])
    inside = (r <= radius) & (r >= obscuration)
    speckle = rng.random(shape) < 0.002  # bright speckle outside, dropouts inside: sub-block noise
    signal = np.where(inside, 100.0, 5.0) + rng.normal(0.0, 3.0, shape)
    signal[speckle & ~inside] = 100.0
    signal[speckle & inside] = 0.0
    return signal


@pytest.fixture
def reference() -> tuple[np.ndarray, ApertureWatch]:
    rng = np.random.default_rng(1)
    signal = _disk_modulation((256, 320), (160, 128), 100, rng)
    found = detect_aperture(signal)
    return signal, ApertureWatch(found.aperture.mask, found.threshold)


def test_a_new_frame_of_the_same_aperture_is_unchanged(reference) -> None:
    _, watch = reference
    again = _disk_modulation((256, 320), (160, 128), 100, np.random.default_rng(2))
    verdict = watch.check(again)
    assert not verdict.changed and verdict.iou > 0.97


@pytest.mark.parametrize(("centre", "radius", "obscuration"), [
    ((172, 128), 100, 0.0),   # shifted by 12 px (about 3 blocks)
    ((160, 128), 88, 0.0),    # 12 % smaller
    ((160, 128), 100, 40.0),  # a central obscuration appeared
])
def test_a_real_change_is_reported(reference, centre, radius, obscuration) -> None:
    _, watch = reference
    moved = _disk_modulation((256, 320), centre, radius, np.random.default_rng(3), obscuration)
    # the full-resolution IoU of these changes is below 0.85; the block check must see them too
    assert watch.check(moved).changed


def test_a_different_shape_or_an_all_dark_frame_is_a_change(reference) -> None:
    _, watch = reference
    assert watch.check(np.zeros((100, 100))).changed
    verdict = watch.check(np.zeros((256, 320)))
    assert verdict.changed and verdict.iou == 0.0
    assert watch.check(np.full((256, 320), np.nan)).changed


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="non-empty 2-D"):
        ApertureWatch(np.zeros((4, 4), bool), 1.0)
    with pytest.raises(ValueError, match="factor"):
        ApertureWatch(np.ones((4, 4), bool), 1.0, factor=0)
    with pytest.raises(ValueError, match="iou_threshold"):
        ApertureWatch(np.ones((4, 4), bool), 1.0, iou_threshold=1.5)
