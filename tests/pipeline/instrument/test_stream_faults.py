"""What a live stream can throw at a phase-shifting processor: an invalid outcome, never an exception."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import FitSettings, InterferometerSettings
from wavestack.pipeline.instrument import SyncFitterSource, processor_for

SETTINGS = InterferometerSettings(fit=FitSettings(method="circle", modes=10, dtype="float64"))


def _set(size: int) -> list[np.ndarray]:
    rows, cols = np.mgrid[:size, :size]
    centre = (size - 1) / 2
    rho2 = ((rows - centre) ** 2 + (cols - centre) ** 2) / (0.42 * size) ** 2
    return [np.where(rho2 < 1, 100 + 80 * np.cos(2 * np.pi * 0.2 * rho2 + k * np.pi / 2), 10) for k in range(4)]


def test_a_set_straddling_a_camera_resize_is_invalid_and_the_next_set_is_measured() -> None:
    processor = processor_for(SETTINGS, SyncFitterSource(SETTINGS.fit))
    assert processor.process(_set(96)).valid
    straddling = _set(96)[:2] + _set(80)[2:]
    outcome = processor.process(straddling)
    assert not outcome.valid
    assert outcome.reason.startswith("phase:") and "differ in shape" in outcome.reason
    confirming = processor.process(_set(80))  # a new aperture is confirmed on the next set
    assert not confirming.valid and confirming.reason.startswith("aperture:")
    after = processor.process(_set(80))
    assert after.valid and after.aperture.mask.shape == (80, 80) and after.aperture.mask.sum() > 0.4 * 80 * 80


def test_a_set_of_the_wrong_length_is_a_wiring_error() -> None:
    settings = InterferometerSettings(fit=SETTINGS.fit, steps_rad=(0.0, np.pi / 2, np.pi, 1.5 * np.pi))
    processor = processor_for(settings, SyncFitterSource(settings.fit))
    with pytest.raises(ValueError, match="expected 4 frame"):
        processor.process(_set(96)[:3])
