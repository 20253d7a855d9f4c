"""What ``bench paper`` keeps for its figures agrees with the row it measured (same fitter, nothing rebuilt)."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.bench import PAPER_APERTURES
from wavestack.bench.paper import benchmark_case
from wavestack.figures.paper_views import basis_gram
from wavestack.pipeline import Aperture, build_fitter


@pytest.mark.parametrize("method, laplacian, balance", [("conformal", "cotangent", False), ("circle", "cotangent", False)])
def test_views_agree_with_the_row(method, laplacian, balance) -> None:
    case = benchmark_case("rounded-rectangle", method, laplacian, balance, size=48, keep_views=True)
    row, views = case.row, case.views
    assert views.label == row.label and views.aperture == "rounded-rectangle"
    # Fig. 6: the kept Gram matrix is the one behind the row's kappa(G)
    eigenvalues = np.linalg.eigvalsh(views.gram)
    # (the smallest eigenvalue of a matrix of condition kappa carries a relative error ~ kappa * 1e-16)
    assert eigenvalues[-1] / eigenvalues[0] == pytest.approx(row.kappa, rel=max(1e-6, 1e-15 * row.kappa))
    # Fig. 7: truth and error live on the aperture's pixels only; the error is a fit error of the table's size
    assert np.array_equal(np.isfinite(views.truth), views.mask) and np.array_equal(np.isfinite(views.error), views.mask)
    rms = float(np.sqrt(np.nanmean(views.error.astype(np.float64) ** 2)))
    assert 0.1 * row.physical_rms <= rms <= 10 * row.physical_rms or rms < 1e-10  # one seed of the median's five
    if method == "circle":
        assert views.mapping is None and row.s95_over_s5 is None
        return
    # Figs. 3-5: the kept per-triangle values give the row's map statistics
    m = views.mapping
    s5, s95 = np.quantile(m.area_scale, [0.05, 0.95], method="inverted_cdf")
    assert s95 / s5 == pytest.approx(row.s95_over_s5, rel=1e-9)
    assert float(np.max(m.beltrami)) == pytest.approx(row.max_beltrami, rel=1e-12)
    assert m.triangles.shape[1] == 3 and m.canonical.shape == m.vertices.shape
    assert np.all(np.hypot(*m.canonical.T) <= 1 + 1e-9)


def test_rows_without_views_keep_nothing() -> None:
    case = benchmark_case("rounded-rectangle", "circle", "cotangent", False, size=48)
    assert case.views is None


def test_basis_gram_is_the_identity_for_an_orthonormal_basis() -> None:
    # qr's own basis is orthonormal on the samples: G = I exactly (to rounding)
    fitter = build_fitter(Aperture.from_mask(PAPER_APERTURES["butterfly"](40)), method="qr", modes=10,
                          dtype=np.float64)
    assert np.allclose(basis_gram(fitter), np.eye(10), atol=1e-10)
