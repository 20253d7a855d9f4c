"""Spike clipping: the residual's spikes are left out, counted and marked, and the fit made without them."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import Aperture, build_fitter
from wavestack.pipeline.instrument import CLIPPED, clip_spikes


def _map_with_spikes(heights: tuple[float, ...] = (2.0, -3.0, 1.5, 0.01, -0.01)
                     ) -> tuple[Aperture, np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """A smooth wavefront with noise (1e-3 waves RMS) and five spikes: three large, two of 10 sigma."""
    rows, cols = np.mgrid[:128, :128]
    x, y = (cols - 63.5) / 60, (63.5 - rows) / 60
    disk = x**2 + y**2 <= 1
    u = x**2 + y**2
    smooth = 0.3 * (2 * u - 1) + 0.1 * (6 * u**2 - 6 * u + 1) + 0.05 * x * (3 * u - 2)
    noise = np.random.default_rng(7).normal(0.0, 1e-3, disk.shape)
    waves = np.where(disk, smooth + noise, np.nan)
    spikes = [(40, 50), (70, 90), (90, 40), (64, 64), (30, 70)]
    for (r, c), height in zip(spikes, heights):
        waves[r, c] += height
    return Aperture.from_mask(disk), waves, smooth, spikes


def test_every_spike_is_left_out_counted_and_marked_and_the_fit_is_the_clean_one() -> None:
    aperture, waves, smooth, spikes = _map_with_spikes()
    fitter = build_fitter(aperture, method="qr", modes=15, dtype=np.float64)
    clean = fitter.fit(np.where(aperture.mask, smooth, np.nan), nan_policy="omit")
    flags = np.where(aperture.mask, 0, 128).astype(np.uint8)
    first = fitter.fit(waves, nan_policy="omit", residual=True)
    # the three large spikes inflate the RMS ~40-fold: one cut at 6 of that RMS misses the 10-sigma two
    assert first.residual_rms > 0.03
    fit, clipped = clip_spikes(fitter, waves, flags, first, 6.0)
    marked = set(zip(*np.nonzero(flags & CLIPPED)))
    assert clipped == len(spikes) and marked == set(spikes)
    assert np.isnan(waves[tuple(np.array(spikes).T)]).all()
    # without them: the noise's RMS, and the coefficients of the spike-free map to the noise's share
    assert fit.residual_rms == pytest.approx(1e-3, rel=0.1)
    assert fit.residual_pv < 12 * fit.residual_rms
    np.testing.assert_allclose(fit.coefficients, clean.coefficients, atol=1e-4)


def test_a_map_without_spikes_is_not_refitted() -> None:
    aperture, waves, _, _ = _map_with_spikes((0.0,) * 5)  # Gaussian noise only: nothing past 6 sigma
    fitter = build_fitter(aperture, method="qr", modes=15, dtype=np.float64)
    flags = np.where(aperture.mask, 0, 128).astype(np.uint8)
    first = fitter.fit(waves, nan_policy="omit", residual=True)
    fit, clipped = clip_spikes(fitter, waves, flags, first, 6.0)
    assert clipped == 0 and fit is first and not (flags & CLIPPED).any()


def _reference_cut(residual: np.ndarray, sigma: float) -> np.ndarray:
    """The cut as the module notes state it, plainly: the limit from the RMS of the pixels still kept."""
    kept = np.isfinite(residual)
    while True:
        limit = max(sigma * np.sqrt(np.mean(residual[kept] ** 2)), 1e-6)
        cut = kept & (np.abs(np.nan_to_num(residual)) > limit)
        if not cut.any():
            return ~kept & np.isfinite(residual)
        kept &= ~cut


@pytest.mark.parametrize("seed", range(4))
def test_the_iterated_cut_is_the_plain_one_on_heavy_tailed_residuals(seed: int) -> None:
    # Student-t residuals (3 degrees of freedom): many rounds, limits falling by less than half
    # as well as by more, so both ways a round walks (the held pixels, the whole map) are taken.
    aperture, _, _, _ = _map_with_spikes()
    rng = np.random.default_rng(seed)
    fitter = build_fitter(aperture, method="qr", modes=15, dtype=np.float64)
    waves = np.where(aperture.mask, 1e-3 * rng.standard_t(3, aperture.mask.shape), np.nan)
    first = fitter.fit(waves, nan_policy="omit", residual=True)
    flags = np.where(aperture.mask, 0, 128).astype(np.uint8)
    _, clipped = clip_spikes(fitter, waves.copy(), flags, first, 3.0)
    expected = _reference_cut(first.residual_map, 3.0)
    assert clipped == int(expected.sum()) > 0
    np.testing.assert_array_equal((flags & CLIPPED) != 0, expected)
