"""Tests for wavestack.pipeline.phase.units: phase, waves, nanometres and surface conversions.

Sign convention checked here: positive phase is positive wavefront, and every conversion
keeps the sign (except a user-chosen negative surface factor).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays
from wavestack.pipeline.phase.units import (
    WavefrontUnits,
    nm_to_phase,
    nm_to_waves,
    phase_to_nm,
    phase_to_waves,
    surface_to_wavefront,
    wavefront_to_surface,
    waves_to_nm,
    waves_to_phase,
)

HENE_NM = 632.8

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
wavelengths = st.floats(1.0, 20_000.0, allow_nan=False)
factors = st.floats(0.01, 10.0, allow_nan=False) | st.floats(-10.0, -0.01, allow_nan=False)
phase_arrays = arrays(np.float64, array_shapes(max_dims=3, max_side=5), elements=finite)


# ----------------------------------------------------------------------------- known values


def test_known_values_at_hene() -> None:
    assert phase_to_waves(2.0 * math.pi) == pytest.approx(1.0)
    assert phase_to_waves(-math.pi) == pytest.approx(-0.5)
    assert waves_to_nm(0.25, HENE_NM) == pytest.approx(158.2)
    assert phase_to_nm(math.pi, HENE_NM) == pytest.approx(316.4)
    assert wavefront_to_surface(316.4) == pytest.approx(158.2)  # reflection, double pass
    assert wavefront_to_surface(316.4, factor=1.0) == pytest.approx(316.4)  # transmission
    assert nm_to_waves(632.8, HENE_NM) == pytest.approx(1.0)
    assert waves_to_phase(0.5) == pytest.approx(math.pi)
    assert nm_to_phase(316.4, HENE_NM) == pytest.approx(math.pi)
    assert surface_to_wavefront(158.2) == pytest.approx(316.4)


def test_oblique_incidence_factor() -> None:
    theta = math.radians(60.0)  # reflection at 60 deg: path change 2 h cos(theta) = h
    factor = 1.0 / (2.0 * math.cos(theta))
    assert wavefront_to_surface(100.0, factor) == pytest.approx(100.0)


def test_sign_is_kept() -> None:
    phase = np.array([-2.0, 0.0, 3.0])
    for out in (
        phase_to_waves(phase),
        phase_to_nm(phase, HENE_NM),
        wavefront_to_surface(phase_to_nm(phase, HENE_NM)),
        WavefrontUnits(HENE_NM).surface_nm(phase),
    ):
        np.testing.assert_array_equal(np.sign(out), np.sign(phase))
    assert wavefront_to_surface(1.0, factor=-0.5) == -0.5  # user-chosen flip


def test_scalars_give_floats_and_arrays_keep_shape_and_nan() -> None:
    assert type(phase_to_waves(1)) is float
    assert type(phase_to_nm(np.float32(1.0), HENE_NM)) is float
    values = np.array([[0.0, np.nan], [math.pi, -math.pi]], dtype=np.float32)
    out = phase_to_nm(values, HENE_NM)
    assert isinstance(out, np.ndarray)
    assert out.dtype == np.float64
    assert out.shape == (2, 2)
    assert np.isnan(out[0, 1])
    assert phase_to_waves([0.0, math.pi]) == pytest.approx([0.0, 0.5])


def test_inputs_are_not_modified() -> None:
    values = np.array([1.0, 2.0])
    phase_to_nm(values, HENE_NM)
    WavefrontUnits(HENE_NM).surface_nm(values)
    np.testing.assert_array_equal(values, [1.0, 2.0])


# ----------------------------------------------------------------------------- round trips


@settings(max_examples=60, deadline=None)
@given(phase_arrays, wavelengths)
def test_round_trip_phase_nm(phase: np.ndarray, wavelength: float) -> None:
    back = nm_to_phase(phase_to_nm(phase, wavelength), wavelength)
    np.testing.assert_allclose(back, phase, rtol=1e-12, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(phase_arrays, wavelengths)
def test_round_trip_phase_waves_nm(phase: np.ndarray, wavelength: float) -> None:
    waves = phase_to_waves(phase)
    np.testing.assert_allclose(waves_to_phase(waves), phase, rtol=1e-12, atol=1e-9)
    nm = waves_to_nm(waves, wavelength)
    np.testing.assert_allclose(nm, phase_to_nm(phase, wavelength), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(nm_to_waves(nm, wavelength), waves, rtol=1e-12, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(phase_arrays, factors)
def test_round_trip_surface(wavefront: np.ndarray, factor: float) -> None:
    surface = wavefront_to_surface(wavefront, factor)
    np.testing.assert_allclose(surface, wavefront * factor, rtol=1e-12, atol=1e-9)
    back = surface_to_wavefront(surface, factor)
    np.testing.assert_allclose(back, wavefront, rtol=1e-12, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(phase_arrays, wavelengths, factors)
def test_dataclass_matches_functions_and_inverts(
    phase: np.ndarray, wavelength: float, factor: float
) -> None:
    units = WavefrontUnits(wavelength_nm=wavelength, surface_factor=factor)
    np.testing.assert_allclose(units.to_waves(phase), phase_to_waves(phase))
    np.testing.assert_allclose(units.to_nm(phase), phase_to_nm(phase, wavelength))
    expected_surface = wavefront_to_surface(phase_to_nm(phase, wavelength), factor)
    np.testing.assert_allclose(units.surface_nm(phase), expected_surface, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(
        units.phase_from_nm(units.to_nm(phase)), phase, rtol=1e-12, atol=1e-9
    )
    np.testing.assert_allclose(
        units.phase_from_surface_nm(units.surface_nm(phase)), phase, rtol=1e-12, atol=1e-9
    )


# ----------------------------------------------------------------------------- dataclass


def test_dataclass_defaults_frozen_and_normalised() -> None:
    units = WavefrontUnits(wavelength_nm=np.float32(632.8))
    assert units.surface_factor == 0.5
    assert type(units.wavelength_nm) is float
    assert units == WavefrontUnits(float(np.float32(632.8)), 0.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        units.wavelength_nm = 500.0  # type: ignore[misc]
    assert WavefrontUnits(HENE_NM, 1).surface_factor == 1.0  # ints accepted


# ----------------------------------------------------------------------------- errors


@pytest.mark.parametrize("bad", [0.0, -632.8, math.nan, math.inf, True, "632.8", None])
def test_bad_wavelength(bad: Any) -> None:
    with pytest.raises(ValueError, match="wavelength_nm must be a finite number > 0"):
        WavefrontUnits(wavelength_nm=bad)
    with pytest.raises(ValueError, match="wavelength_nm must be a finite number > 0"):
        phase_to_nm(1.0, bad)
    with pytest.raises(ValueError, match="wavelength_nm"):
        nm_to_waves(1.0, bad)


@pytest.mark.parametrize("bad", [0.0, -0.0, math.nan, -math.inf, False, "0.5"])
def test_bad_surface_factor(bad: Any) -> None:
    with pytest.raises(ValueError, match="surface_factor must be a finite non-zero number"):
        WavefrontUnits(HENE_NM, surface_factor=bad)
    with pytest.raises(ValueError, match="factor must be a finite non-zero number"):
        wavefront_to_surface(1.0, bad)
    with pytest.raises(ValueError, match="factor must be a finite non-zero number"):
        surface_to_wavefront(1.0, bad)


@pytest.mark.parametrize("bad", [np.array([1j]), np.array([True]), "1.0", [None]])
def test_bad_values(bad: Any) -> None:
    with pytest.raises(ValueError, match="phase must be real numeric"):
        phase_to_waves(bad)
    with pytest.raises(ValueError, match="phase must be real numeric"):
        WavefrontUnits(HENE_NM).surface_nm(bad)
    with pytest.raises(ValueError, match="wavefront must be real numeric"):
        wavefront_to_surface(bad)
