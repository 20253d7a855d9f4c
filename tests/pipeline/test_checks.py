"""Tests for wavestack.pipeline._checks: the argument checks shared by the pipeline topics."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from wavestack.pipeline import _checks


@pytest.mark.parametrize("value", [0, 7, -3, np.int64(5), np.uint8(2)])
def test_integers_are_integers(value: object) -> None:
    assert _checks.is_integer(value)
    assert _checks.is_real(value)


@pytest.mark.parametrize("value", [True, np.bool_(False), 1.0, "1", None, np.float64(2.0)])
def test_booleans_and_others_are_not_integers(value: object) -> None:
    assert not _checks.is_integer(value)


@pytest.mark.parametrize("value", [True, np.bool_(True), "1.5", None, 1j])
def test_booleans_and_others_are_not_real(value: object) -> None:
    assert not _checks.is_real(value)


def test_finite_real() -> None:
    assert _checks.is_finite_real(np.float32(1.5))
    assert not _checks.is_finite_real(math.inf)
    assert not _checks.is_finite_real(math.nan)


@pytest.mark.parametrize(
    ("voice", "message"),
    [
        ("must", "size must be an integer >= 2, got 1"),
        ("expected", "size: expected an integer >= 2, got 1"),
        ("is", "size is 1; expected an integer >= 2"),
    ],
)
def test_int_at_least_voices(voice: str, message: str) -> None:
    assert _checks.int_at_least(np.int32(2), "size", 2, voice=voice) == 2  # type: ignore[arg-type]
    with pytest.raises(ValueError) as info:
        _checks.int_at_least(1, "size", 2, voice=voice)  # type: ignore[arg-type]
    assert str(info.value) == message


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (0.0, "wavelength_nm must be a finite number > 0 (nm), got 0.0"),
        (math.inf, "wavelength_nm must be a finite number > 0 (nm), got inf"),
        (True, "wavelength_nm must be a finite number > 0 (nm), got True"),
    ],
)
def test_real_at_least_refuses(value: object, message: str) -> None:
    with pytest.raises(ValueError) as info:
        _checks.real_at_least(value, "wavelength_nm", 0.0, strict=True, unit="nm")
    assert str(info.value) == message


def test_real_at_least_accepts_the_bound_unless_strict() -> None:
    assert _checks.real_at_least(0, "gap", 0.0) == 0.0
    assert isinstance(_checks.real_at_least(Fraction(1, 2), "gap", 0.0), float)
    with pytest.raises(ValueError, match="gap is 0; expected a finite number > 0"):
        _checks.real_at_least(0, "gap", 0.0, strict=True, voice="is")


def test_one_of_voices() -> None:
    assert _checks.one_of("graph", "laplacian", ("cotangent", "graph")) == "graph"
    with pytest.raises(ValueError) as info:
        _checks.one_of("x", "laplacian", ("cotangent", "graph"), voice="expected")
    assert str(info.value) == "laplacian: expected one of cotangent, graph, got 'x'"
    with pytest.raises(ValueError) as info:
        _checks.one_of("x", "ordering", ("noll", "ansi"))
    assert str(info.value) == "ordering must be one of ('noll', 'ansi'), got 'x'"


def test_number_checks() -> None:
    assert _checks.as_int(np.int16(3), "j") == 3
    assert _checks.positive_int(4, "n") == 4
    assert _checks.finite_float(np.float32(0.5), "x") == 0.5
    assert _checks.positive_float(2, "pitch") == 2.0
    with pytest.raises(ValueError, match="j must be an integer, got 3.0"):
        _checks.as_int(3.0, "j")
    with pytest.raises(ValueError, match="n must be >= 1, got 0"):
        _checks.positive_int(0, "n")
    with pytest.raises(ValueError, match="n must be a positive integer, got True"):
        _checks.positive_int(True, "n")
    with pytest.raises(ValueError, match="x must be finite, got nan"):
        _checks.finite_float(math.nan, "x")
    with pytest.raises(ValueError, match=r"pitch must be > 0, got -1.0"):
        _checks.positive_float(-1, "pitch")


def test_array_checks() -> None:
    out = _checks.real_array(np.arange(3, dtype=np.int8), "phase")
    assert out.dtype == np.float64
    with pytest.raises(ValueError, match="phase must be real numeric, got dtype bool"):
        _checks.real_array(np.zeros(2, dtype=bool), "phase")
    with pytest.raises(ValueError, match="phase must be real numeric, got dtype complex128"):
        _checks.real_array(np.zeros(2, dtype=complex), "phase")
    image = np.zeros((2, 3), dtype=np.uint16)
    assert _checks.real_image(image, "frame") is image
    with pytest.raises(ValueError, match="frame must be a 2-D array"):
        _checks.real_image(np.zeros(3), "frame")
    with pytest.raises(ValueError, match="frame must hold real numbers"):
        _checks.real_image(np.zeros((2, 2), dtype=bool), "frame")


def test_optional_mask() -> None:
    assert _checks.optional_mask(None, (4, 4), min_true=1, shape_of="that of the frame") is None
    mask = np.ones((4, 4), dtype=bool)
    assert _checks.optional_mask(mask, (4, 4), min_true=16, shape_of="that of the frame") is not None
    with pytest.raises(ValueError, match="mask: expected a boolean array, got dtype uint8"):
        _checks.optional_mask(mask.astype(np.uint8), (4, 4), min_true=1, shape_of="x")
    with pytest.raises(ValueError, match=r"mask: expected shape \(4, 5\) \(that of a frame\), got \(4, 4\)"):
        _checks.optional_mask(mask, (4, 5), min_true=1, shape_of="that of a frame")
    with pytest.raises(ValueError, match="mask: expected at least 17 true pixels"):
        _checks.optional_mask(mask, (4, 4), min_true=17, shape_of="x")
