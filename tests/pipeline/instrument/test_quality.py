"""The data-quality mask's saturation: a frame at full scale on the fit grid, in any frame of the set."""

from __future__ import annotations

import numpy as np

from wavestack.pipeline.instrument import SATURATED, QualitySettings, mark_quality

_ADOPTED = np.zeros((8, 8), np.uint8)  # every grid pixel inside and fitted
_LABELS = (np.ones((8, 8), np.int32), 2)


def _saturated(frames: list[np.ndarray], settings: QualitySettings) -> list[list[int]]:
    mask = mark_quality(np.zeros((8, 8)), np.ones((16, 16)), frames, 2, _ADOPTED, _LABELS, settings)
    assert np.isnan(mask.waves[(mask.flags & SATURATED) != 0]).all()
    return np.argwhere(mask.flags & SATURATED).tolist()


def test_a_pixel_is_saturated_where_any_frame_reaches_full_scale_on_the_grid() -> None:
    frames = [np.full((16, 16), 100, np.uint16) for _ in range(3)]
    frames[1][4, 6] = 4095  # the grid's pixel (2, 3): every second pixel each way
    frames[2][5, 7] = 4095  # between grid pixels: not measured, not marked
    assert _saturated(frames, QualitySettings(saturation_counts=4095)) == [[2, 3]]
    assert _saturated(frames, QualitySettings()) == []  # uint16's own full scale, 65535, is reached nowhere
    frames[0][0, 0] = 65535
    assert _saturated(frames, QualitySettings()) == [[0, 0]]


def test_float_frames_saturate_only_at_a_configured_level_and_mixed_types_are_read_alike() -> None:
    frames = [np.full((16, 16), 100.0) for _ in range(2)]
    frames[1][4, 6] = 1e9
    assert _saturated(frames, QualitySettings()) == []  # a float frame has no full scale of its own
    assert _saturated(frames, QualitySettings(saturation_counts=4095)) == [[2, 3]]
    frames[0] = frames[0].astype(np.uint16)  # a set of two types
    assert _saturated(frames, QualitySettings(saturation_counts=4095)) == [[2, 3]]
