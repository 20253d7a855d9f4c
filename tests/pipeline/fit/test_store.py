"""Saved fitters: a loaded fitter gives the same results; the store builds once, then loads."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.bench import annulus_circular_hole_mask, butterfly_mask
from wavestack.pipeline import build_fitter
from wavestack.pipeline.fit.store import FitterStore, fitter_key, load_fitter, save_fitter


def _frame(mask: np.ndarray, seed: int) -> np.ndarray:
    rows, cols = np.indices(mask.shape)
    rng = np.random.default_rng(seed)
    values = 1e-3 * (rows - 60.0) + 2e-5 * (cols - 50.0) ** 2 + rng.normal(0, 1e-3, mask.shape)
    return np.where(mask, values, np.nan)


@pytest.mark.parametrize(
    "settings",
    [
        dict(method="csf-qcm", modes=21, mesh_vertices=3000, remove="ptt", dtype=np.float32),
        dict(method="qr", modes=66, dtype=np.float64),  # mode-major operator
        dict(method="circle", modes=15, ordering="fringe", pupil=(64.0, 64.0, 70.0)),
    ],
)
def test_saved_and_loaded_fitter_fit_identically(tmp_path, settings) -> None:
    mask = annulus_circular_hole_mask(128) if settings["method"] == "csf-qcm" else butterfly_mask(128)
    fitter = build_fitter(mask, **settings)
    path = tmp_path / "fitter.npz"
    save_fitter(fitter, path)
    loaded = load_fitter(path)
    frame = _frame(mask, 1)
    a, b = fitter.fit(frame, residual=True), loaded.fit(frame, residual=True)
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    assert a.residual_rms == b.residual_rms and a.residual_pv == b.residual_pv
    if a.circle_coefficients is not None:
        np.testing.assert_array_equal(a.circle_coefficients, b.circle_coefficients)
    if a.removed is not None:
        assert a.removed == b.removed
    assert loaded.basis == fitter.basis
    assert loaded.diagnostics.as_dict() == fitter.diagnostics.as_dict()
    np.testing.assert_array_equal(loaded.aperture.mask, fitter.aperture.mask)
    np.testing.assert_array_equal(loaded.surface(a.coefficients), fitter.surface(a.coefficients))


def test_store_builds_once_then_loads(tmp_path, caplog) -> None:
    mask = butterfly_mask(96)
    store = FitterStore(tmp_path / "fitters")
    first = store.get_or_build(mask, method="csf-qcm", modes=10, mesh_vertices=2000)
    files = list((tmp_path / "fitters").glob("fitter-*.npz"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    with caplog.at_level("INFO", logger="wavestack.pipeline.fit.store"):
        second = store.get_or_build(mask, method="csf-qcm", modes=10, mesh_vertices=2000)
    assert "loaded fitter" in caplog.text and files[0].stat().st_mtime_ns == stamp
    assert second.mapping is None and first.mapping is not None  # the map itself is not stored
    frame = _frame(mask, 2)
    np.testing.assert_array_equal(first.fit(frame).coefficients, second.fit(frame).coefficients)
    # other settings or another mask: another file
    store.get_or_build(mask, method="csf-qcm", modes=11, mesh_vertices=2000)
    store.get_or_build(np.rot90(mask), method="csf-qcm", modes=10, mesh_vertices=2000)
    assert len(list((tmp_path / "fitters").glob("fitter-*.npz"))) == 3


def test_key_depends_on_mask_and_settings() -> None:
    mask = butterfly_mask(64)
    key = fitter_key(mask, {"method": "qr", "modes": 10})
    assert key == fitter_key(mask.astype(np.uint8) * 255, {"modes": 10, "method": "qr"})
    assert key != fitter_key(mask, {"method": "qr", "modes": 11})
    flipped = mask.copy()
    flipped[0, 0] = ~flipped[0, 0]
    assert key != fitter_key(flipped, {"method": "qr", "modes": 10})


def test_unreadable_or_foreign_files_are_rejected(tmp_path) -> None:
    foreign = tmp_path / "other.npz"
    np.savez(foreign, data=np.zeros(3))
    with pytest.raises(ValueError, match="not a wavestack fitter"):
        load_fitter(foreign)
    store = FitterStore(tmp_path)
    mask = butterfly_mask(64)
    path = store.path_for(mask, {"method": "qr", "modes": 6})
    path.write_bytes(b"truncated")
    fitter = store.get_or_build(mask, method="qr", modes=6)  # rebuilt, not crashed
    assert fitter.n_modes == 6 and load_fitter(path).n_modes == 6
