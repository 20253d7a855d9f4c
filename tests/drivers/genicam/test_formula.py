"""The SwissKnife formula language: what each operator computes, and hostile formulas refused."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from wavestack.drivers.genicam.formula import (MAX_FORMULA_CHARS, MAX_NESTING, FormulaError, evaluate, parse_formula,
                                               variables)

INT64 = st.integers(-(2**63), 2**63 - 1)


def run(text: str, integer: bool = True, **values: float) -> float:
    return evaluate(parse_formula(text), values.__getitem__, integer=integer)


def c_division(a: int, b: int) -> int:
    """C's truncating division, computed without the code under test."""
    return int(a / b) if abs(a) < 2**52 and abs(b) < 2**52 else (abs(a) // abs(b)) * (1 if (a < 0) == (b < 0) else -1)


@pytest.mark.parametrize(("text", "expected"), [
    ("1 + 2 * 3", 7), ("(1 + 2) * 3", 9), ("2 ** 3 ** 2", 512), ("-2 ** 2", -4), ("7 / 2", 3), ("-7 / 2", -3),
    ("-7 % 2", -1), ("1 << 4 >> 2", 4), ("0xF0 & 0x3C | 1", 0x31), ("5 ^ 1", 4), ("~0", -1), ("!0 + !5", 1),
    ("3 = 3", 1), ("3 <> 3", 0), ("2 < 3 && 3 <= 3", 1), ("0 || 0", 0), ("4 >= 5 ? 10 : 20", 20),
    ("1 ? 2 ? 3 : 4 : 5", 3), ("ABS(-3) + SGN(-8) + NEG(2)", 0), ("TRUNC(2.7) + FLOOR(-0.5) + CEIL(0.2)", 2),
    ("ROUND(2.5) + ROUND(-2.5)", 0), ("0xffffffff + 1", 2**32), ("0x7fffffffffffffff + 1", -(2**63)),
])
def test_integer_formulas(text: str, expected: int) -> None:
    assert run(text) == expected


def test_float_formulas_and_constants() -> None:
    assert run("7 / 2", integer=False) == 3.5
    assert run("ROUND(PI, 3)", integer=False) == 3.142
    assert run("SQRT(16) + LN(E) + LG(100) + EXP(0)", integer=False) == 8.0
    assert run("SIN(0) + COS(0) + TAN(0) + ATAN(0) + ASIN(0) + ACOS(1)", integer=False) == 1.0
    assert run("2 ** 100", integer=False) == 2.0**100
    assert run("(P1=1)?(TO*P2/1000):(TO)", integer=False, P1=1, P2=20000, TO=100) == 2000.0  # Basler's exposure


def test_only_the_branch_taken_reads_its_variables() -> None:
    read: list[str] = []

    def lookup(name: str) -> int:
        read.append(name)
        return {"SEL": 1, "A": 5}[name]
    assert evaluate(parse_formula("(SEL = 1) ? A : B"), lookup, integer=True) == 5
    assert read == ["SEL", "A"]


@pytest.mark.parametrize(("text", "message"), [
    ("1 / 0", "division by zero"), ("5 % (2 - 2)", "division by zero"), ("1 << 64", "shift count"),
    ("1 >> -1", "shift count"), ("2 ** -1", "negative integer power"), ("SQRT(-1)", "cannot evaluate"),
    ("X + 1", "X"),
])
def test_evaluation_errors(text: str, message: str) -> None:
    with pytest.raises(FormulaError, match=message):
        evaluate(parse_formula(text), {"Y": 1}.__getitem__ if "X" not in text else _undefined, integer=True)


def _undefined(name: str) -> int:
    raise FormulaError(f"variable {name} is not defined")


@pytest.mark.parametrize("text", ["", "1 +", "(1", "1)", "1 ? 2", "FOO(1)", "ROUND(1, 2, 3)", "1 $ 2", "3 4"])
def test_syntax_errors(text: str) -> None:
    with pytest.raises(FormulaError):
        parse_formula(text)


def test_hostile_formulas_are_refused_before_any_evaluation() -> None:
    with pytest.raises(FormulaError, match="nesting"):
        parse_formula("(" * (MAX_NESTING + 1) + "1" + ")" * (MAX_NESTING + 1))
    with pytest.raises(FormulaError, match="nesting"):
        parse_formula("-" * 200 + "1")
    with pytest.raises(FormulaError, match="characters"):
        parse_formula("1+" * MAX_FORMULA_CHARS + "1")
    # a huge exponent is bounded work: 64-bit arithmetic, never a giant integer
    assert run("3 ** 100000000000") == pow(3, 100000000000, 2**64) - (2**64 if pow(3, 100000000000, 2**64) >= 2**63 else 0)


@fuzz_settings(300)
@given(a=INT64, b=INT64)
def test_integer_arithmetic_is_c_int64(a: int, b: int) -> None:
    wrap = lambda v: (v + 2**63) % 2**64 - 2**63  # noqa: E731
    assert run("A + B", A=a, B=b) == wrap(a + b)
    assert run("A * B", A=a, B=b) == wrap(a * b)
    assert run("A & B", A=a, B=b) == a & b and run("A | B", A=a, B=b) == a | b
    if b != 0:
        assert run("A / B", A=a, B=b) == wrap(c_division(a, b))
        assert run("A - (A / B) * B", A=a, B=b) == run("A % B", A=a, B=b)


@fuzz_settings(300)
@given(text=st.text(alphabet="0123456789xabcdefABCDEF()+-*/%&|^~!?:=<>. ,PIESGNROUD", max_size=60))
def test_any_text_parses_and_evaluates_or_raises_formula_error(text: str) -> None:
    try:
        tree = parse_formula(text)
        value = evaluate(tree, lambda name: 3, integer=False)
    except FormulaError:
        return
    assert isinstance(value, (int, float)) and (isinstance(value, int) or math.isfinite(value))
    assert all(name in text for name in variables(tree))
