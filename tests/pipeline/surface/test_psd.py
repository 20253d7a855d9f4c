"""The windowed PSD on any aperture: power laws, band-limited RMS, normalisation, and no filling."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline.surface import aperture_outline, aperture_window, measured_area, psd_window, surface_psd

N = 512
PIXEL_MM = 0.1


def _power_law_surface(amplitude: float, slope: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A periodic random surface whose 2-D PSD is ``amplitude f^slope`` (nm^2 mm^2), and |f| of its grid.

    Fourier coefficients of variance PSD df^2 and random phase; the real part of their inverse
    transform keeps half the variance, restored by sqrt(2).
    """
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(N, PIXEL_MM), np.fft.fftfreq(N, PIXEL_MM)))
    df = 1.0 / (N * PIXEL_MM)
    scale = np.zeros_like(f)
    scale[f > 0] = np.sqrt(amplitude * f[f > 0] ** slope) * df
    rng = np.random.default_rng(seed)
    coefficients = scale * (rng.normal(size=f.shape) + 1j * rng.normal(size=f.shape)) / np.sqrt(2)
    return np.real(np.fft.ifft2(coefficients)) * N * N * np.sqrt(2), f


def _band_passed(surface: np.ndarray, f: np.ndarray, low: float, high: float) -> np.ndarray:
    return np.real(np.fft.ifft2(np.fft.fft2(surface) * ((f >= low) & (f <= high))))


def _rounded_rectangle() -> np.ndarray:
    rows, cols = np.indices((N, N))
    dx, dy = np.abs(cols - 255.5) - (240 - 30), np.abs(rows - 255.5) - (100 - 30)
    return np.hypot(np.maximum(dx, 0), np.maximum(dy, 0)) <= 30


def _annulus() -> np.ndarray:
    radius = np.hypot(*(np.indices((N, N)) - 255.5))
    return (radius <= 240) & (radius >= 90)


@pytest.mark.parametrize("aperture", [_rounded_rectangle, _annulus], ids=["rounded rectangle", "annulus"])
def test_a_power_law_surface_gives_its_slope_and_its_band_rms(aperture) -> None:
    """Every one of eight realisations, not only the typical one: the slope within 0.05 of the truth."""
    mask = aperture()
    low, high = 0.3, 3.0
    area = measured_area(mask)
    window = psd_window(area)
    weights = aperture_window(aperture_outline(mask)) ** 2
    slopes, bands = [], []
    for seed in range(8):
        surface, f = _power_law_surface(amplitude=2.0, slope=-3.0, seed=seed)
        psd = surface_psd(area, np.where(mask, surface, np.nan), PIXEL_MM, window=window)
        law = psd.power_law(low, high)
        slopes.append(law.slope)
        assert law.amplitude == pytest.approx(2.0, rel=0.15)  # 1 cycle/mm lies inside the band
        # the band's truth on this aperture: the surface's content in the band (filtered on the
        # whole periodic grid, where it is known exactly), weighted over the area as the window
        # weighs it; the estimate differs from it only by what the window leaks into the band
        band = _band_passed(surface, f, low, high)
        bands.append(psd.band_rms_nm(low, high) / np.sqrt(np.sum(weights * band**2) / np.sum(weights)))
    assert np.max(np.abs(np.asarray(slopes) + 3.0)) <= 0.05, slopes
    assert np.max(np.abs(np.asarray(bands) - 1.0)) <= 0.03, bands


def test_band_rms_on_square_fully_measured_data_matches_an_independent_computation() -> None:
    """Sinusoids of known amplitude, some inside the band: the band holds exactly their power."""
    rows, cols = np.indices((256, 256)) * 0.2  # mm
    rng = np.random.default_rng(3)
    frequencies = [0.12, 0.21, 0.33, 0.47, 0.62, 0.8, 1.05, 1.3, 1.7, 2.1]  # cycles/mm; band 0.25-1.5
    amplitudes = rng.uniform(1.0, 5.0, len(frequencies))
    surface = np.zeros((256, 256))
    for frequency, amplitude in zip(frequencies, amplitudes):
        angle = rng.uniform(0, np.pi)
        surface += amplitude * np.sin(2 * np.pi * frequency * (cols * np.cos(angle) + rows * np.sin(angle))
                                      + rng.uniform(0, 2 * np.pi))
    inside = [a for f, a in zip(frequencies, amplitudes) if 0.25 <= f <= 1.5]
    expected = np.sqrt(np.sum(np.square(inside)) / 2)  # a sinusoid's mean square is a^2 / 2
    psd = surface_psd(measured_area(np.ones((256, 256), bool)), surface, 0.2)
    assert psd.band_rms_nm(0.25, 1.5) == pytest.approx(expected, rel=0.02)


def test_the_recoloured_spectrum_integrates_to_the_differences_mean_square() -> None:
    """Parseval for the prewhitened estimate: ``PSD2 D`` integrates to the windowed differences' mean square."""
    mask = _annulus()
    surface, _ = _power_law_surface(amplitude=1.0, slope=-2.0, seed=1)
    psd = surface_psd(measured_area(mask), surface, PIXEL_MM)
    fx, fy = np.meshgrid(psd.fx_per_mm, psd.fy_per_mm)
    response = 4 * np.sin(np.pi * fx * PIXEL_MM) ** 2 + 4 * np.sin(np.pi * fy * PIXEL_MM) ** 2
    step = (psd.fx_per_mm[1] - psd.fx_per_mm[0]) * (psd.fy_per_mm[1] - psd.fy_per_mm[0])
    # written out: neighbours both inside, the geometric mean of their window values, each axis's
    # weighted least-squares plane of the differences removed; the origin (D = 0) holds no power,
    # so its share, the weighted sum squared over the grid's size, is left out
    window = aperture_window(aperture_outline(mask))
    expected = 0.0
    for axis in (0, 1):
        pairs = mask & np.roll(mask, -1, axis)
        pairs[(slice(-1, None), slice(None))[::1 - 2 * axis]] = False  # no wrap-around pair
        weight = np.where(pairs, np.sqrt(window * np.roll(window, -1, axis)), 0.0)
        difference = np.roll(surface, -1, axis) - surface
        rows, cols = np.nonzero(pairs)
        design = np.column_stack([np.ones(rows.size), cols, rows])
        plane = np.linalg.lstsq(design * weight[pairs][:, None], difference[pairs] * weight[pairs], rcond=None)[0]
        difference = np.where(pairs, difference - (plane[0] + plane[1] * np.indices(mask.shape)[1]
                                                   + plane[2] * np.indices(mask.shape)[0]), 0.0)
        origin = np.sum(weight * difference) ** 2 / fx.size
        expected += (np.sum((weight * difference) ** 2) - origin) / np.sum(weight**2)
    assert np.sum(psd.psd2_nm2_mm2 * response) * step == pytest.approx(expected, rel=1e-9)
    # the 1-D form integrates to nearly what the 2-D spectrum holds on the same rings: ring k holds
    # about 2 pi k samples, off by a few per cent on the first rings (ring 1 holds 8, not 6.28), so
    # from the fourth ring on (the corners of the frequency square lie outside the last ring)
    ring_step = psd.frequency_per_mm[1] - psd.frequency_per_mm[0]
    ring = np.rint(np.hypot(fx, fy) / ring_step)
    on_rings = (ring >= 4) & (ring <= psd.frequency_per_mm.size)
    from_fourth = psd.frequency_per_mm >= 4 * ring_step * (1 - 1e-9)
    assert np.sum(psd.radial_nm2_mm[from_fourth]) * ring_step == pytest.approx(
        np.sum(psd.psd2_nm2_mm2[on_rings]) * step, rel=0.02)


def test_dropouts_are_windowed_not_filled() -> None:
    """Missing pixels inside the aperture leave the spectrum alone; filling them does not."""
    mask = _annulus()
    surface, f = _power_law_surface(amplitude=1.0, slope=-3.0, seed=5)
    holes = mask.copy()
    holes[np.random.default_rng(0).random(mask.shape) < 0.002] = False
    holes[200:206, 300:340] = False
    low, high = 3.0, 5.0  # the short periods, where a surface has least power and a fill's steps most
    full = surface_psd(measured_area(mask), surface, PIXEL_MM).band_rms_nm(low, high)
    windowed = surface_psd(measured_area(holes), np.where(holes, surface, np.nan), PIXEL_MM).band_rms_nm(low, high)
    filled_map = np.where(holes, surface, np.nanmean(surface[holes]))  # what the window must never do
    filled = surface_psd(measured_area(mask), filled_map, PIXEL_MM).band_rms_nm(low, high)
    assert windowed == pytest.approx(full, rel=0.05)
    assert filled > 1.2 * full  # the steps of a constant fill: 29 % more in this band


@pytest.mark.parametrize(("band", "message"), [
    ((0.001, 1.0), r"band 0\.001-1 cycles/mm .*resolves 0\.0208\d*-5 cycles/mm"),
    ((0.1, 9.0), r"band 0\.1-9 cycles/mm .*expected a band inside it"),
    ((2.0, 1.0), r"expected two frequencies 0 < low < high"),
])
def test_a_band_the_sampling_cannot_resolve_is_refused(band: tuple[float, float], message: str) -> None:
    psd = surface_psd(measured_area(_annulus()), np.zeros((N, N)), PIXEL_MM)
    with pytest.raises(ValueError, match=message):
        psd.band_rms_nm(*band)
    with pytest.raises(ValueError, match=message):
        psd.power_law(*band)
