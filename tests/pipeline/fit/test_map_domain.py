"""The domain a mapped method maps: the aperture trimmed to the fitted pixels, drop-outs filled."""

from __future__ import annotations

import numpy as np

from wavestack.pipeline import Aperture, DetectionSettings, Topology, build_fitter, detect_aperture, read_measured_map
from wavestack.pipeline.fit.map_domain import map_domain

from shared_data import DATA, require_shared_data


def _disk(radius: float, size: int = 81) -> np.ndarray:
    rows, cols = np.mgrid[:size, :size]
    return np.hypot(rows - size // 2, cols - size // 2) <= radius


def test_the_domain_is_the_fitted_region_with_its_drop_outs_and_not_the_overhang() -> None:
    outline = _disk(38)
    fitted = _disk(35)  # the outline reaches 3 px past the outermost fitted pixels
    fitted[40, 30:33] = fitted[20, 50] = False  # drop-outs
    domain = map_domain(Aperture.from_mask(outline), fitted)
    assert np.array_equal(domain.mask, _disk(35))
    assert domain.topology is Topology.SIMPLY_CONNECTED


def test_an_obscuration_of_the_aperture_stays_a_hole() -> None:
    outline = _disk(38) & ~_disk(10)
    fitted = _disk(36) & ~_disk(11)
    domain = map_domain(Aperture.from_mask(outline), fitted)
    assert domain.topology is Topology.DOUBLY_CONNECTED
    assert np.array_equal(domain.mask, fitted)


def test_fitted_pixels_that_are_the_aperture_give_the_aperture_back() -> None:
    aperture = Aperture.from_mask(_disk(30))
    assert map_domain(aperture, aperture.mask) is aperture
    assert map_domain(aperture, None) is aperture


@require_shared_data()
def test_the_real_strip_in_its_detected_outline_fits_as_on_its_own_pixels() -> None:
    """The real 259 x 33 Zygo strip inside the outline detected from its pixels (what ``analyze``
    maps): the detection's closing bridges the pixel staircase of the slanted sides, yet the
    csf-qcm fit of the measured pixels is the one the map of those pixels gives."""
    valid = np.asarray(read_measured_map(DATA / "external" / "monolithic_zygo_test.datx").valid)
    outline = detect_aperture(valid.astype(np.float64), DetectionSettings(threshold=0.5)).aperture.mask | valid
    assert np.count_nonzero(outline & ~valid) > 500  # the outline does overhang the staircase
    on_outline = build_fitter(Aperture.from_mask(outline), method="csf-qcm", fit_mask=valid, dtype=np.float64)
    on_pixels = build_fitter(valid, method="csf-qcm", dtype=np.float64)
    kappa = on_outline.diagnostics.gram_condition
    # the same map, the same samples: the same Gram matrix to rounding
    assert abs(kappa - on_pixels.diagnostics.gram_condition) <= 1e-9 * kappa
    assert kappa <= 20.0
