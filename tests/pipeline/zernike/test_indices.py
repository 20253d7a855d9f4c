"""Tests for the Noll / ANSI / Fringe index conventions and coefficient conversion."""

from __future__ import annotations

import itertools
import math
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.pipeline.zernike.circle import zernike_basis
from wavestack.pipeline.zernike.normalisation import (
    Normalisation,
    default_normalisation,
    normalisation_factor,
)
from wavestack.pipeline.zernike.modes import Ordering, validate_mode
from wavestack.pipeline.zernike.indices import (
    ansi_to_nm,
    first_index,
    fringe_to_nm,
    index_to_nm,
    mode_list,
    nm_to_ansi,
    nm_to_fringe,
    nm_to_index,
    nm_to_noll,
    noll_to_nm,
)
from wavestack.pipeline.zernike.conversion import convert_coefficients
from wavestack.pipeline.zernike.names import mode_name

ORDERINGS: tuple[Ordering, ...] = ("noll", "ansi", "fringe")
NORMALISATIONS: tuple[Normalisation, ...] = ("rms", "edge")
FIRST = {"noll": 1, "ansi": 0, "fringe": 1}


def all_modes(n_max: int) -> list[tuple[int, int]]:
    """Every valid (n, m) with n <= n_max."""
    return [(n, m) for n in range(n_max + 1) for m in range(-n, n + 1, 2)]


def fringe_reference(groups: int) -> list[tuple[int, int]]:
    """Fringe order written straight from its definition, groups d = 0 .. groups-1.

    Group d = (n + |m|)/2; inside it |m| descends from d to 0, cosine before sine.
    """
    modes: list[tuple[int, int]] = []
    for d in range(groups):
        for m_abs in range(d, -1, -1):
            n = 2 * d - m_abs
            modes.extend([(n, m_abs), (n, -m_abs)] if m_abs else [(n, 0)])
    return modes


# --------------------------------------------------------------------------- round trips


@settings(database=None, deadline=None, max_examples=300)
@given(ordering=st.sampled_from(ORDERINGS), offset=st.integers(min_value=0, max_value=500))
def test_index_round_trip_property(ordering: Ordering, offset: int) -> None:
    j = FIRST[ordering] + offset
    n, m = index_to_nm(j, ordering)
    assert validate_mode(n, m) == (n, m)
    assert nm_to_index(n, m, ordering) == j


@st.composite
def valid_modes(draw: st.DrawFn) -> tuple[int, int]:
    n = draw(st.integers(min_value=0, max_value=60))
    m_abs = draw(st.sampled_from(range(n % 2, n + 1, 2)))
    sign = draw(st.sampled_from((1, -1)))
    return n, sign * m_abs


@settings(database=None, deadline=None, max_examples=300)
@given(ordering=st.sampled_from(ORDERINGS), mode=valid_modes())
def test_mode_round_trip_property(ordering: Ordering, mode: tuple[int, int]) -> None:
    j = nm_to_index(*mode, ordering)
    assert j >= FIRST[ordering]
    assert index_to_nm(j, ordering) == mode


@pytest.mark.parametrize("ordering", ORDERINGS)
def test_index_round_trip_loop(ordering: Ordering) -> None:
    first = FIRST[ordering]
    seen = set()
    for j in range(first, first + 501):
        mode = index_to_nm(j, ordering)
        assert nm_to_index(*mode, ordering) == j
        seen.add(mode)
    assert len(seen) == 501  # injective on the range


def test_dispatchers_match_specific_functions() -> None:
    for j in range(1, 200):
        assert index_to_nm(j, "noll") == noll_to_nm(j)
        assert index_to_nm(j, "fringe") == fringe_to_nm(j)
        assert index_to_nm(j - 1, "ansi") == ansi_to_nm(j - 1)
    for n, m in all_modes(12):
        assert nm_to_index(n, m, "noll") == nm_to_noll(n, m)
        assert nm_to_index(n, m, "ansi") == nm_to_ansi(n, m)
        assert nm_to_index(n, m, "fringe") == nm_to_fringe(n, m)
    assert [first_index(o) for o in ORDERINGS] == [1, 0, 1]


# --------------------------------------------------------------------------- known terms


def test_noll_first_terms() -> None:
    # Noll (1976), Table I: Z2 = 2 r cos, Z3 = 2 r sin, Z5 = sqrt6 r^2 sin 2t,
    # Z6 = sqrt6 r^2 cos 2t, Z7 = coma sin, Z8 = coma cos, Z9 = trefoil sin, Z10 cos.
    expected = [
        (0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2),
        (3, -1), (3, 1), (3, -3), (3, 3), (4, 0),
    ]  # fmt: skip
    assert [noll_to_nm(j) for j in range(1, 12)] == expected


def test_noll_parity_rule() -> None:
    for j in range(2, 400):
        n, m = noll_to_nm(j)
        if m != 0:
            assert (m > 0) == (j % 2 == 0), f"Noll j={j} -> {(n, m)} breaks the parity rule"


def test_ansi_first_terms() -> None:
    expected = [(0, 0), (1, -1), (1, 1), (2, -2), (2, 0), (2, 2), (3, -3), (3, -1), (3, 1), (3, 3)]
    assert [ansi_to_nm(j) for j in range(10)] == expected
    for n, m in all_modes(15):
        assert nm_to_ansi(n, m) == (n * (n + 2) + m) // 2


def test_fringe_first_37_terms() -> None:
    expected = fringe_reference(6) + [(12, 0)]  # groups d = 0..5 hold 36 terms
    assert len(expected) == 37
    assert [fringe_to_nm(j) for j in range(1, 38)] == expected
    # A few entries of the published table, as literal values.
    assert fringe_to_nm(4) == (2, 0)
    assert fringe_to_nm(5) == (2, 2)
    assert fringe_to_nm(9) == (4, 0)
    assert fringe_to_nm(16) == (6, 0)
    assert fringe_to_nm(36) == (10, 0)


def test_fringe_extension_past_37() -> None:
    # Group 6 without (12, 0) fills 38..49, then group 7 starts at 50 = 7^2 + 1.
    group6 = [mode for mode in fringe_reference(7)[36:] if mode != (12, 0)]
    assert [fringe_to_nm(j) for j in range(38, 50)] == group6
    assert [fringe_to_nm(j) for j in range(50, 65)] == fringe_reference(8)[49:]
    # The first (D+1)^2 indices hold exactly the groups d <= D, for every D.
    for groups in range(1, 16):
        first_block = {fringe_to_nm(j) for j in range(1, groups**2 + 1)}
        assert first_block == set(fringe_reference(groups))


@pytest.mark.parametrize("ordering", ORDERINGS)
def test_every_mode_up_to_n20_appears_once(ordering: Ordering) -> None:
    wanted = set(all_modes(20))
    assert len(wanted) == 231
    last = max(nm_to_index(n, m, ordering) for n, m in wanted)
    block = mode_list(ordering, last - FIRST[ordering] + 1)
    assert len(set(block)) == len(block)  # no mode twice
    assert wanted <= set(block)
    if ordering in ("noll", "ansi"):  # sorted by n: the first 231 are exactly n <= 20
        assert set(mode_list(ordering, 231)) == wanted


def test_mode_list() -> None:
    assert mode_list("noll", 0) == []
    assert mode_list("ansi", 3) == [(0, 0), (1, -1), (1, 1)]
    assert mode_list("fringe", 4) == [(0, 0), (1, 1), (1, -1), (2, 0)]


# --------------------------------------------------------------------------- normalisation


def test_default_normalisation() -> None:
    assert default_normalisation("noll") == "rms"
    assert default_normalisation("ansi") == "rms"
    assert default_normalisation("fringe") == "edge"


def test_normalisation_factor() -> None:
    # Noll (1976): Z1 = 1, Z2 = 2 r cos t, Z4 = sqrt3 (2 r^2 - 1), Z6 = sqrt6 r^2 cos 2t.
    assert normalisation_factor(0, 0, "rms") == 1.0
    assert normalisation_factor(1, 1, "rms") == pytest.approx(2.0, rel=1e-15)
    assert normalisation_factor(2, 0, "rms") == pytest.approx(math.sqrt(3.0), rel=1e-15)
    assert normalisation_factor(2, -2, "rms") == pytest.approx(math.sqrt(6.0), rel=1e-15)
    for n, m in all_modes(10):
        assert normalisation_factor(n, m, "edge") == 1.0


# --------------------------------------------------------------------------- conversion


@pytest.mark.parametrize(
    ("source", "target", "source_norm", "target_norm"),
    list(itertools.product(ORDERINGS, ORDERINGS, NORMALISATIONS, NORMALISATIONS)),
)
def test_convert_keeps_the_surface(
    source: Ordering, target: Ordering, source_norm: Normalisation, target_norm: Normalisation
) -> None:
    seed = zlib.crc32(f"{source}/{target}/{source_norm}/{target_norm}".encode())
    rng = np.random.default_rng(seed)
    coefficients = rng.normal(size=40)
    converted = convert_coefficients(
        coefficients,
        source,
        target,
        source_normalisation=source_norm,
        target_normalisation=target_norm,
    )
    radius = np.sqrt(rng.uniform(0.0, 1.0, 200))
    angle = rng.uniform(0.0, 2.0 * np.pi, 200)
    x, y = radius * np.cos(angle), radius * np.sin(angle)
    source_basis = zernike_basis(mode_list(source, coefficients.size), x, y, source_norm)
    target_basis = zernike_basis(mode_list(target, converted.size), x, y, target_norm)
    before = source_basis @ coefficients
    after = target_basis @ converted
    # Each converted coefficient carries one rounding of the ratio N_s/N_t; relative to the
    # sum of |terms| the surfaces must then agree to a few 1e-16, so 1e-13 has wide margin
    # yet catches any wrong ratio or misplaced mode (errors of order 1).
    scale = np.abs(source_basis) @ np.abs(coefficients)
    np.testing.assert_array_less(np.abs(after - before), 1e-13 * scale + 1e-300)
    # The default length is minimal: the last coefficient is a mode the source had.
    assert converted[-1] != 0.0


def test_convert_round_trip_and_explicit_count() -> None:
    rng = np.random.default_rng(7)
    noll = rng.normal(size=28)
    fringe = convert_coefficients(noll, "noll", "fringe", count=60)
    assert fringe.size == 60
    back = convert_coefficients(fringe, "fringe", "noll", count=28)
    # Two multiplications by reciprocal factors: agreement to a few ulp.
    np.testing.assert_allclose(back, noll, rtol=1e-14, atol=0)


def test_convert_edge_to_rms_divides_by_factor() -> None:
    # 1 unit of Fringe (edge) defocus = 1/sqrt(3) units of Noll (rms) Z4.
    fringe = np.zeros(9)
    fringe[3] = 1.0  # Fringe j = 4 is (2, 0)
    noll = convert_coefficients(fringe, "fringe", "noll")
    assert noll.size == nm_to_noll(2, 0)
    assert noll[nm_to_noll(2, 0) - 1] == pytest.approx(1.0 / math.sqrt(3.0), rel=1e-15)


def test_convert_default_count_is_minimal() -> None:
    fringe = np.zeros(37)
    fringe[36] = 2.5  # Fringe j = 37 is (12, 0)
    noll = convert_coefficients(fringe, "fringe", "noll")
    expected_length = 12 * 13 // 2 + 1  # Noll: 78 modes with n < 12, then (12, 0)
    assert noll.size == expected_length
    assert noll[-1] == pytest.approx(2.5 / math.sqrt(13.0), rel=1e-15)
    assert convert_coefficients(np.zeros(5), "noll", "ansi").size == 0


def test_convert_lost_non_zero_mode_raises() -> None:
    noll = np.zeros(10)
    noll[9] = 1.0  # Noll j = 10 is (3, 3); Fringe puts it at 10
    with pytest.raises(ValueError, match=r"\(3, 3\).*noll index 10"):
        convert_coefficients(noll, "noll", "fringe", count=9)
    noll[9] = 0.0  # a zero coefficient may be dropped silently
    assert convert_coefficients(noll, "noll", "fringe", count=9).size == 9


@pytest.mark.parametrize(
    "kwargs",
    [
        {"coefficients": np.zeros((2, 3))},
        {"coefficients": [1.0, float("nan")]},
        {"coefficients": np.array([1.0 + 1.0j])},
        {"coefficients": ["a"]},
        {"source": "zemax"},
        {"target": "osa"},
        {"source_normalisation": "peak"},
        {"target_normalisation": "unit"},
        {"count": -1},
        {"count": 2.0},
    ],
)
def test_convert_rejects_bad_input(kwargs: dict[str, object]) -> None:
    arguments: dict[str, object] = {"coefficients": [1.0, 2.0], "source": "noll", "target": "ansi"}
    arguments.update(kwargs)
    with pytest.raises(ValueError):
        convert_coefficients(**arguments)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("function", "argument", "message"),
    [
        (noll_to_nm, 0, "j must be >= 1"),
        (fringe_to_nm, 0, "j must be >= 1"),
        (ansi_to_nm, -1, "j must be >= 0"),
        (noll_to_nm, 2.0, "integer"),
        (ansi_to_nm, True, "integer"),
    ],
)
def test_bad_index_raises(function: object, argument: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        function(argument)  # type: ignore[operator]


@pytest.mark.parametrize(
    ("n", "m", "message"),
    [(2, 1, "even"), (1, 3, r"\|m\| <= n"), (3, -5, r"\|m\| <= n"), (-2, 0, "n must be >= 0")],
)
@pytest.mark.parametrize("function", [nm_to_noll, nm_to_ansi, nm_to_fringe, validate_mode])
def test_bad_mode_raises(function: object, n: int, m: int, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        function(n, m)  # type: ignore[operator]


def test_bad_ordering_and_normalisation_raise() -> None:
    with pytest.raises(ValueError, match="ordering"):
        index_to_nm(1, "zemax")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="ordering"):
        mode_list("osa", 3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="count"):
        mode_list("noll", -1)
    with pytest.raises(ValueError, match="normalisation"):
        normalisation_factor(2, 0, "peak")  # type: ignore[arg-type]


def test_mode_names() -> None:
    assert mode_name(0, 0) == "piston"
    assert mode_name(*noll_to_nm(2)) == "tilt x"
    assert mode_name(*noll_to_nm(3)) == "tilt y"
    assert mode_name(2, 0) == "defocus"
    assert mode_name(3, -1) == "coma y"
    assert mode_name(4, 0) == "primary spherical"
    assert mode_name(9, 3) == "Z(9,3)"
    with pytest.raises(ValueError):
        mode_name(2, 1)
