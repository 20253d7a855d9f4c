"""Piston and tilt removal (the one removal the station, the fit and the polishing loop use)."""

from __future__ import annotations

import numpy as np
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.pipeline import remove_physical_terms


@fuzz_settings(200)
@given(st.integers(3, 30), st.integers(3, 30), st.floats(-5, 5), st.floats(-1, 1), st.floats(-1, 1),
       st.integers(0, 2**32 - 1))
def test_ptt_removal_removes_exactly_a_plane(h: int, w: int, piston: float, tip: float, tilt: float,
                                             seed: int) -> None:
    rng = np.random.default_rng(seed)
    mask = rng.random((h, w)) < 0.7
    rows, cols = np.nonzero(mask)
    if rows.size < 3 or np.linalg.matrix_rank(np.column_stack([np.ones(rows.size), rows, cols])) < 3:
        return
    surface = rng.normal(size=(h, w))
    r, c = np.mgrid[0:h, 0:w]
    once = remove_physical_terms(surface, mask, "ptt")[0]
    again = remove_physical_terms(surface + piston + tip * r + tilt * c, mask, "ptt")[0]
    np.testing.assert_allclose(once[mask], again[mask], atol=1e-8)
    # what is left is orthogonal to the plane
    design = np.column_stack([np.ones(rows.size), rows, cols])
    np.testing.assert_allclose(design.T @ once[mask], 0.0, atol=1e-8)
