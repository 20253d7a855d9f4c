"""The residual's peak-to-valley on the fit grid against the fitter's own residual map."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import build_fitter
from wavestack.station import ResidualPeakToValley


def _map_and_mask() -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.mgrid[-40:41, -40:41] / 40.0
    mask = (xx ** 2 + yy ** 2 <= 1.0) & (xx ** 2 + (yy - 0.2) ** 2 >= 0.09)  # an off-centre obscuration
    rng = np.random.default_rng(1)
    # piston, tilts and power (what remove= takes out), plus noise and a spike the fit cannot follow
    waves = 2.0 + 0.5 * xx - 0.3 * yy + 0.3 * (xx ** 2 + yy ** 2) + 0.01 * rng.standard_normal(xx.shape)
    waves[20, 40] += 0.2
    waves[45, 30] = np.nan  # omitted by the fit, and by the peak-to-valley
    return waves, mask


@pytest.mark.parametrize("method", ["qr", "circle", "csf-qcm"])
@pytest.mark.parametrize("remove", [None, "ptt", "pttp"])
def test_equals_the_fitters_residual_pv(method: str, remove: str | None) -> None:
    waves, mask = _map_and_mask()
    fitter = build_fitter(mask, method=method, modes=15, remove=remove, mesh_vertices=2000)
    fit = fitter.fit(waves, nan_policy="omit")
    reference = fitter.fit(waves, nan_policy="omit", residual=True)
    pv = ResidualPeakToValley()
    found = pv(fitter, waves, fit)
    # the same residual with the terms in float32 instead of float64: maps of ~3 waves, 15-19 terms,
    # float32's 6e-8 relative rounding -> a few 1e-7 waves (measured 3e-7 at most)
    assert found == pytest.approx(reference.residual_pv, abs=2e-6)
    assert found > 0.2  # the spike is in it
    again = pv(fitter, waves, fitter.fit(waves, nan_policy="omit"))  # the fitter's arrays are kept
    assert again == found


def test_follows_a_new_fitter_and_an_all_nan_map_has_none() -> None:
    waves, mask = _map_and_mask()
    pv = ResidualPeakToValley()
    small = mask & (np.arange(81)[:, None] < 60)
    for aperture in (mask, small):
        fitter = build_fitter(aperture, method="qr", modes=10, remove="ptt")
        fit = fitter.fit(waves, nan_policy="omit")
        expected = fitter.fit(waves, nan_policy="omit", residual=True).residual_pv
        assert pv(fitter, waves, fit) == pytest.approx(expected, abs=2e-6)
    assert np.isnan(pv(fitter, np.full_like(waves, np.nan), fit))
