"""Slope maps and RMS slope over an integration length, against slopes written out here."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.surface import measured_area, slope_maps


def _disk(size: int = 121, radius: float = 58) -> np.ndarray:
    return np.hypot(*(np.indices((size, size)) - (size - 1) / 2)) <= radius


def test_a_sinusoid_has_the_slope_of_its_finite_difference_over_the_length() -> None:
    """z = a sin(2 pi x / p): over a length L the slope is a (sin(k(x + L)) - sin(kx)) / L, RMS a sin(kL/2) 2/L / sqrt 2."""
    mask = _disk()
    pixel, period, amplitude = 0.05, 0.8, 20.0  # mm, mm, nm
    cols = np.indices(mask.shape)[1] * pixel
    surface = amplitude * np.sin(2 * np.pi * cols / period)
    for length in (0.1, 0.25, 0.4):  # 2, 5 and 8 pixels; 0.4 mm is half a period
        figures = slope_maps(measured_area(mask), surface, pixel, length).figures()
        k = 2 * np.pi / period
        expected = amplitude * 2 * abs(np.sin(k * length / 2)) / length / np.sqrt(2)  # nm/mm = urad
        # the disk holds 7.5 periods, not a whole number: the mean square of the samples is
        # within a few tenths of a percent of a^2/2
        assert figures.rms_x_urad == pytest.approx(expected, rel=0.01), length
        assert figures.rms_y_urad < 1e-9


def test_a_length_between_pixels_interpolates_the_far_height() -> None:
    """On a quadratic z = c x^2 the slope over L is c (2 x + L): a half-pixel length gives the half step."""
    mask = np.ones((40, 60), bool)
    pixel = 0.1
    x = np.indices(mask.shape)[1] * pixel
    maps = slope_maps(measured_area(mask), 3.0 * x**2, pixel, 0.25)  # 2.5 pixels
    # tilt removed: what is left is 2 c (x - mean x) over the defined slopes
    defined = np.isfinite(maps.x_urad)
    starts = np.nonzero(defined[0])[0] - 1  # each slope sits one pixel (round(2.5 / 2)) after its start
    expected = 3.0 * (2 * starts * pixel + 0.25)
    assert np.allclose(maps.x_urad[0, defined[0]], expected - expected.mean(), atol=1e-9)


def test_y_points_up() -> None:
    mask = np.ones((50, 50), bool)
    y = (24.5 - np.indices(mask.shape)[0]) * 0.1  # mm, up
    maps = slope_maps(measured_area(mask), y**2, 0.1, 0.3)  # dz/dy = 2 y: positive at the top
    column = maps.y_urad[:, 25]
    finite = np.isfinite(column)
    assert column[finite][0] > 4.0 and column[finite][-1] < -4.0
    assert np.all(np.diff(column[finite]) < 0)  # rows go down, y up: the slope falls with the row


def test_only_measured_pixels_enter() -> None:
    mask = _disk()
    surface = np.where(mask, 0.0, np.nan)
    surface[mask & (np.indices(mask.shape)[1] > 60)] = 0.0
    maps = slope_maps(measured_area(mask), surface, 0.1, 0.3)
    assert np.all(np.isnan(maps.x_urad[~mask]))
    assert maps.figures().rms_urad == 0.0


@pytest.mark.parametrize(("length", "message"), [
    (0.15, r"slope integration length 0\.15 mm is 1\.5 pixels of 0\.1 mm; expected at least 2 pixels \(0\.2 mm\)"),
    (20.0, r"slope integration length 20 mm: expected a length shorter than the measured area"),
    (-1.0, r"slope integration length \(mm\) must be > 0, got -1\.0"),
])
def test_bad_integration_lengths_are_refused_in_one_line(length: float, message: str) -> None:
    mask = _disk()
    with pytest.raises(ValueError, match=message):
        slope_maps(measured_area(mask), np.zeros(mask.shape), 0.1, length)
