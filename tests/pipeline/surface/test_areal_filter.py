"""Areal Gaussian filters: ISO 16610-21's transmission, 60 dB out of band, 0.5 % in it, 50 % at cut-off.

The expected transmission is the Gaussian's, written here: ``2^-(lc / l)^2`` for the low-pass
(``exp(-pi alpha^2 (lc/l)^2)`` with ``alpha^2 = ln 2 / pi``). Figures are read where the whole
weighting function lies inside the aperture (more than 1.1 cut-offs from the edge); nearer the
edge the normalised convolution keeps constants exactly but its one-sided weights transmit
otherwise (a test below shows how much).
"""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.surface import filter_surface, measured_area, parse_areal_filter

SIZE, PIXEL = 400, 0.05  # 20 mm across
RADIUS_PX = 190


def _disk() -> tuple[np.ndarray, np.ndarray]:
    radius = np.hypot(*(np.indices((SIZE, SIZE)) - (SIZE - 1) / 2))
    return radius <= RADIUS_PX, radius


def _wave(wavelength_mm: float) -> np.ndarray:
    rows, cols = np.indices((SIZE, SIZE)) * PIXEL
    return np.sin(2 * np.pi * (0.8 * cols + 0.6 * rows) / wavelength_mm + 0.3)


def _low_pass(wavelength: float, cutoff: float) -> float:
    return 2.0 ** (-((cutoff / wavelength) ** 2))


def _interior(radius: np.ndarray, cutoff_mm: float) -> np.ndarray:
    return radius <= RADIUS_PX - 1.1 * cutoff_mm / PIXEL


@pytest.mark.parametrize("kind", ["lp", "hp"])
def test_low_and_high_pass_transmit_as_the_gaussian_at_every_wavelength(kind: str) -> None:
    mask, radius = _disk()
    cutoff = 1.0
    interior = _interior(radius, cutoff)
    for wavelength in (0.25, 0.3125, 0.5, 1.0, 2.0, 4.0, 12.0):
        wave = _wave(wavelength)
        out = filter_surface(measured_area(mask), wave, PIXEL, parse_areal_filter(f"{kind}:{cutoff}"))
        gain = _low_pass(wavelength, cutoff) if kind == "lp" else 1.0 - _low_pass(wavelength, cutoff)
        # the filtered map is the wave times the transmission, pixel by pixel
        assert np.max(np.abs(out[interior] - gain * wave[interior])) < 1e-8, wavelength


def test_iso_targets_60_db_out_of_band_half_a_percent_in_band_half_at_cut_off() -> None:
    mask, radius = _disk()
    area = measured_area(mask)
    cutoff = 1.0
    interior = _interior(radius, cutoff)

    def gain(kind: str, wavelength: float) -> float:
        wave = _wave(wavelength)
        out = filter_surface(area, wave, PIXEL, parse_areal_filter(f"{kind}:{cutoff}"))
        return float(np.sqrt(np.sum(out[interior] ** 2) / np.sum(wave[interior] ** 2)))

    assert 20 * np.log10(gain("lp", cutoff / 3.2)) <= -60.0  # stop band of the low-pass
    assert abs(gain("lp", 12 * cutoff) - 1.0) <= 0.005  # pass band of the low-pass
    assert 20 * np.log10(gain("hp", 30 * cutoff)) <= -60.0  # stop band of the high-pass (1 - T ~ ln 2 (lc/l)^2)
    assert abs(gain("hp", cutoff / 3.2) - 1.0) <= 0.005  # pass band of the high-pass
    assert gain("lp", cutoff) == pytest.approx(0.5, abs=1e-3)
    assert gain("hp", cutoff) == pytest.approx(0.5, abs=1e-3)


def test_band_pass_keeps_the_band_and_halves_each_cut_off() -> None:
    mask, radius = _disk()
    area = measured_area(mask)
    band = parse_areal_filter("bp:0.4,4")
    interior = _interior(radius, 4.0)
    for wavelength in (0.12, 0.4, 0.9, 4.0, 16.0):
        expected = _low_pass(wavelength, 0.4) - _low_pass(wavelength, 4.0)
        wave = _wave(wavelength)
        out = filter_surface(area, wave, PIXEL, band)
        assert np.max(np.abs(out[interior] - expected * wave[interior])) < 1e-7, wavelength
    assert _low_pass(0.4, 0.4) - _low_pass(0.4, 4.0) == pytest.approx(0.5, abs=1e-9)
    assert _low_pass(4.0, 0.4) - _low_pass(4.0, 4.0) == pytest.approx(0.5, abs=0.01)


def test_the_edge_is_not_pulled_toward_zero() -> None:
    """Normalised inside the aperture: a constant stays constant to the last pixel; without the
    normalisation the edge would fall to about half."""
    mask, radius = _disk()
    area = measured_area(mask)
    out = filter_surface(area, np.full(mask.shape, 7.0), PIXEL, parse_areal_filter("lp:2"))
    assert np.allclose(out[mask], 7.0, atol=1e-9)
    # at the rim a wave 12 cut-offs long is kept within 8 % (the one-sided weights' centroid lies
    # inside the rim, so a slope shifts the mean), and a wave of a quarter cut-off is attenuated
    # by 15 dB only (the one-sided weights' transform decays slowly): the 60 dB hold inside
    long_wave = filter_surface(area, _wave(24.0), PIXEL, parse_areal_filter("lp:2"))
    assert np.max(np.abs(long_wave[mask] - _wave(24.0)[mask])) < 0.1
    short_wave = filter_surface(area, _wave(0.5), PIXEL, parse_areal_filter("lp:2"))
    assert np.max(np.abs(short_wave[mask])) < 0.2


@pytest.mark.parametrize(("text", "message"), [
    ("lp:0.05", r"cut-off 0\.05 mm is outside what the sampling resolves; expected 0\.1 mm \(two pixels\)"),
    ("hp:25", r"cut-off 25 mm is outside .* to 19 mm \(the measured area's extent\)"),
    ("bp:2,1", r"short cut-off before the long one"),
    ("xx:1", r"expected lp:CUTOFF_MM, hp:CUTOFF_MM or bp:SHORT_MM,LONG_MM"),
    ("lp:a", r"expected lp:CUTOFF_MM"),
    ("bp:1", r"expected lp:CUTOFF_MM"),
])
def test_bad_filters_are_refused_in_one_line(text: str, message: str) -> None:
    mask, _ = _disk()
    with pytest.raises(ValueError, match=message):
        filter_surface(measured_area(mask), np.zeros(mask.shape), PIXEL, parse_areal_filter(text))
