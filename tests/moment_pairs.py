"""The moment refit against the operator refit of the same settings: one comparison for every basis
the moment path serves (``tests/pipeline/fit/test_moments.py``, ``test_annulus.py``)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import assume

from wavestack.pipeline import IllConditionedBasis, build_fitter


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def _terms(removed) -> np.ndarray:
    return np.array([removed.piston, removed.tilt_x, removed.tilt_y, removed.power or 0.0])


def assert_same_fit(a, b, frame: np.ndarray) -> None:
    """``a`` (moments) and ``b`` (operator) agree to the issue's 1e-9.

    The build accepts moments only where their rounding, measured ~30 * 1.1e-16 *
    moment_amplification, stays at 1e-10; the operator's is ~1e-15. Coefficients are compared
    relative to their norm, or to the frame's RMS where they vanish (a lone piston mode under
    ``remove="ptt"``: 0 against 1e-32).
    """
    energy = float(np.nanmean(frame[np.isfinite(frame)] ** 2))
    difference = np.linalg.norm(a.coefficients - b.coefficients)
    assert difference <= 1e-9 * max(np.linalg.norm(b.coefficients), np.sqrt(energy))
    if b.circle_coefficients is not None:
        assert _relative(a.circle_coefficients, b.circle_coefficients) <= 1e-9
    if b.removed is not None:
        assert _relative(_terms(a.removed), _terms(b.removed)) <= 1e-9
    # The residual comes from the identity |w|^2 - c.b: its rounding scales with the frame's
    # energy, so the squared RMS is compared to 1e-9 of the mean square of the samples.
    assert abs(a.residual_rms**2 - b.residual_rms**2) <= 1e-9 * energy
    assert a.valid_count == b.valid_count and a.nan_count == b.nan_count


def moments_match_or_refuse(mask: np.ndarray, settings: dict, frame_of: Callable) -> None:
    """Build with ``refit="auto"`` and ``"operator"``; the moments (where chosen) fit ``frame_of(operator)``
    as the operator does, and where auto kept the operator, ``refit="moments"`` refuses."""
    try:
        operator = build_fitter(mask, refit="operator", **settings)
    except IllConditionedBasis:
        assume(False)  # too many modes for this aperture: no path builds (checked elsewhere)
    chosen = build_fitter(mask, **settings)
    assert chosen.basis == operator.basis
    frame = frame_of(operator)
    if chosen.refit == "operator":  # auto kept the operator: only where moments would lose precision
        with pytest.raises(ValueError, match="would lose precision"):
            build_fitter(mask, refit="moments", **settings)
        return
    assert chosen.diagnostics.moment_amplification <= 3e4
    assert_same_fit(chosen.fit(frame), operator.fit(frame), frame)
