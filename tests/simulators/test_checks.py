"""The simulators' shared argument checks (``wavestack.simulators._checks``, private: tested as internals)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavestack.simulators._checks import (check_bit_depth, check_image_size, check_seed, finite_number, is_integer,
                                          is_number, nonnegative_number, number_pair, read_only, read_only_copy)


def test_number_and_integer_predicates() -> None:
    assert is_number(1) and is_number(np.float32(0.5)) and not is_number(True) and not is_number("1")
    assert is_integer(3) and is_integer(np.uint8(3)) and not is_integer(3.0) and not is_integer(False)


def test_finite_number_messages_name_the_argument() -> None:
    assert finite_number(np.int32(4), "pitch_px", minimum=4.0) == 4.0
    with pytest.raises(ValueError, match=r"^pitch_px: expected a number, got 'a'$"):
        finite_number("a", "pitch_px")
    with pytest.raises(ValueError, match=r"^pitch_px: expected a finite number, got nan$"):
        finite_number(math.nan, "pitch_px")
    with pytest.raises(ValueError, match=r"^pitch_px: expected >= 4.0, got 3$"):
        finite_number(3, "pitch_px", minimum=4.0)
    with pytest.raises(ValueError, match=r"^gain_px: expected > 0.0, got 0$"):
        finite_number(0, "gain_px", above=0.0)


def test_nonnegative_and_pair() -> None:
    assert nonnegative_number(0, "halo") == 0.0
    with pytest.raises(ValueError, match=r"^halo: expected a number >= 0, got -0.1$"):
        nonnegative_number(-0.1, "halo")
    assert number_pair((1, 2.5), "centre_px") == (1.0, 2.5)
    with pytest.raises(ValueError, match=r"^centre_px: expected a pair of numbers, got 1$"):
        number_pair(1, "centre_px")
    with pytest.raises(ValueError, match=r"^centre_px\[1\]: expected a finite number"):
        number_pair((1, math.inf), "centre_px")


def test_camera_checks() -> None:
    for depth in (8, 12, 16):
        check_bit_depth(depth)
    with pytest.raises(ValueError, match=r"^bit_depth: expected 8, 12 or 16, got 10$"):
        check_bit_depth(10)
    check_seed(np.int64(0))
    with pytest.raises(ValueError, match=r"^seed: expected an integer >= 0, got -1$"):
        check_seed(-1)
    check_image_size(8, np.int16(9), 8)
    with pytest.raises(ValueError, match=r"^width: expected an integer >= 8 pixels, got 7$"):
        check_image_size(8, 7, 8)
    with pytest.raises(ValueError, match=r"^height: expected an integer >= 2 pixels, got True$"):
        check_image_size(True, 4, 2)


def test_read_only_marks_in_place_and_the_copy_copies() -> None:
    array = np.zeros(3)
    assert read_only(array) is array and not array.flags.writeable
    source = np.arange(3)
    copy = read_only_copy(source)
    assert copy.dtype == np.float64 and not copy.flags.writeable and copy is not source
