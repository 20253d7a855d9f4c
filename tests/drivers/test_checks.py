"""The drivers' shared argument checks (``wavestack.drivers._checks``, private: tested as internals)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavestack.drivers._checks import check_timeout, is_finite_real, is_integral_in, is_number, read_only_copy


@pytest.mark.parametrize("value", [0, -3, 2.5, np.int16(4), np.float32(1.5), math.inf])
def test_numbers_are_numbers(value: object) -> None:
    assert is_number(value)


@pytest.mark.parametrize("value", [True, False, None, "1", [1.0], 1j])
def test_bools_and_non_numbers_are_not(value: object) -> None:
    assert not is_number(value)


def test_finite_real_takes_python_numbers_only() -> None:
    assert is_finite_real(0) and is_finite_real(-1.25) and is_finite_real(np.float64(2.0))  # a float subclass
    for value in (True, math.nan, math.inf, -math.inf, np.float32(1.0), np.int64(1), "1", None):
        assert not is_finite_real(value), value


def test_integral_in_range() -> None:
    assert is_integral_in(0, 0, 0xFFFF) and is_integral_in(0xFFFF, 0, 0xFFFF) and is_integral_in(3.0, 1, 3)
    assert not is_integral_in(0x10000, 0, 0xFFFF)
    assert not is_integral_in(-1, 0, 0xFFFF)
    assert not is_integral_in(2.5, 0, 10)
    assert not is_integral_in(True, 0, 1)


def test_integral_in_lets_int_raise_for_non_numbers() -> None:
    # the register codecs have always let int() speak for None, text and NaN
    with pytest.raises(TypeError):
        is_integral_in(None, 0, 1)
    with pytest.raises(ValueError):
        is_integral_in(math.nan, 0, 1)


@pytest.mark.parametrize("timeout_s", [0.0, -1.0, math.inf, math.nan])
def test_timeout_must_be_finite_and_positive(timeout_s: float) -> None:
    with pytest.raises(ValueError, match=r"timeout_s must be a finite number > 0"):
        check_timeout(timeout_s)
    check_timeout(1e-6)


def test_read_only_copy_is_a_float64_copy() -> None:
    source = np.array([1, 2, 3])
    out = read_only_copy(source)
    assert out.dtype == np.float64 and not out.flags.writeable
    source[0] = 9
    assert out[0] == 1.0
