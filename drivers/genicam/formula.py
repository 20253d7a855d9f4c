"""The GenApi formula language of SwissKnife, IntSwissKnife, Converter and IntConverter nodes.

A formula is parsed once into a tree of tuples (:func:`parse_formula`) and evaluated as often as
needed (:func:`evaluate`), with the variables looked up lazily, so a branch of ``?:`` that is not
taken reads no register. Nothing is handed to Python's ``eval``: the grammar below is the whole
language.

Operators, loosest first: ``?:``; ``||``; ``&&``; ``|``; ``^``; ``&``; ``=`` ``<>``; ``<`` ``<=``
``>`` ``>=``; ``<<`` ``>>``; ``+`` ``-``; ``*`` ``/`` ``%``; ``**`` (right-associative); unary ``-``
``+`` ``~`` ``!``. Functions: ``SGN NEG ABS SQRT EXP LN LG SIN COS TAN ASIN ACOS ATAN TRUNC FLOOR
CEIL`` of one argument and ``ROUND(x[, digits])``; constants ``PI`` and ``E``. Numbers are decimal,
``0x`` hexadecimal or decimal fractions with an optional exponent.

Integer formulas (``IntSwissKnife``, ``IntConverter``) compute in signed 64-bit arithmetic as the
reference implementation does: ``/`` truncates towards zero, ``%`` takes the dividend's sign, and
every result wraps to 64 bits. Float formulas compute in double precision; bitwise operators and
shifts act on their operands truncated to 64-bit integers. Comparisons and logical operators give
1 or 0.

Hostile formulas are refused, never run unbounded: more than :data:`MAX_FORMULA_CHARS` characters
or a nesting deeper than :data:`MAX_NESTING` at parse time; a division by zero, a shift count
outside 0..63, a negative integer power or a non-finite result at evaluation. Each raises
:class:`FormulaError`, which the node map turns into one ``ProtocolError`` naming the device and
the node.

Reference: EMVA GenICam Standard, GenApi, section "SwissKnife" (formula syntax and operators).

Example
-------
>>> tree = parse_formula("(SEL = 2) ? 0x100 + 4 * IDX : 0")
>>> evaluate(tree, {"SEL": 2, "IDX": 3}.__getitem__, integer=True)
268
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Union

MAX_FORMULA_CHARS = 16384
MAX_NESTING = 64

Number = Union[int, float]
Tree = tuple  # ("num", v) | ("var", name) | ("unary", op, a) | ("binary", op, a, b) | ("if", c, a, b) | ("call", f, args)

_TOKEN = re.compile(r"""\s*(?:
    (?P<hex>0[xX][0-9a-fA-F]+)
  | (?P<number>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_.]*)
  | (?P<op>\*\*|<<|>>|<=|>=|<>|!=|&&|\|\||[-+*/%&|^~!?:=<>(),])
)""", re.VERBOSE)

# binary operators: precedence (higher binds tighter)
_BINARY = {"||": 1, "&&": 2, "|": 3, "^": 4, "&": 5, "=": 6, "<>": 6, "!=": 6, "<": 7, "<=": 7, ">": 7,
           ">=": 7, "<<": 8, ">>": 8, "+": 9, "-": 9, "*": 10, "/": 10, "%": 10, "**": 11}
_UNARY_PRECEDENCE = 12  # binds tighter than every binary operator but ** on its right: -2**2 == -4
_FUNCTIONS_1 = {
    "SGN": lambda x: (x > 0) - (x < 0), "NEG": lambda x: -x, "ABS": abs, "SQRT": math.sqrt, "EXP": math.exp,
    "LN": math.log, "LG": math.log10, "SIN": math.sin, "COS": math.cos, "TAN": math.tan, "ASIN": math.asin,
    "ACOS": math.acos, "ATAN": math.atan, "TRUNC": math.trunc, "FLOOR": math.floor, "CEIL": math.ceil,
}
_CONSTANTS = {"PI": math.pi, "E": math.e}
_INT64 = 1 << 64


class FormulaError(ValueError):
    """A formula that cannot be parsed or evaluated; the message says where and why."""


def _wrap(value: int) -> int:
    """Two's-complement wrap of an integer to signed 64 bits."""
    value &= _INT64 - 1
    return value - _INT64 if value >= 1 << 63 else value


def _tokens(text: str) -> list[str]:
    if len(text) > MAX_FORMULA_CHARS:
        raise FormulaError(f"formula of {len(text)} characters; at most {MAX_FORMULA_CHARS} are accepted")
    tokens: list[str] = []
    position = 0
    stripped = text.rstrip()
    while position < len(stripped):
        match = _TOKEN.match(stripped, position)
        if match is None or match.end() == position:
            raise FormulaError(f"unexpected character {stripped[position:position + 1]!r} at {position} "
                               f"in {_excerpt(text)}")
        tokens.append(match.group(match.lastgroup or "op"))
        position = match.end()
    return tokens


def _excerpt(text: str) -> str:
    return repr(text if len(text) <= 80 else text[:77] + "...")


class _Parser:
    """Precedence climbing over the token list; depth counts nested sub-expressions."""

    def __init__(self, text: str) -> None:
        self._text = text
        self._tokens = _tokens(text)
        self._at = 0
        self._depth = 0

    def _peek(self) -> str | None:
        return self._tokens[self._at] if self._at < len(self._tokens) else None

    def _take(self, expected: str | None = None) -> str:
        token = self._peek()
        if token is None or (expected is not None and token != expected):
            found = "the end" if token is None else repr(token)
            raise FormulaError(f"expected {expected or 'an operand'!r}, found {found} in {_excerpt(self._text)}")
        self._at += 1
        return token

    def parse(self) -> Tree:
        if not self._tokens:
            raise FormulaError("empty formula")
        tree = self._expression()
        if self._peek() is not None:
            raise FormulaError(f"unexpected {self._peek()!r} after a complete expression in {_excerpt(self._text)}")
        return tree

    def _expression(self) -> Tree:
        self._depth += 1
        if self._depth > MAX_NESTING:
            raise FormulaError(f"nesting deeper than {MAX_NESTING} levels in {_excerpt(self._text)}")
        try:
            condition = self._binary(1)
            if self._peek() != "?":
                return condition
            self._take("?")
            when_true = self._expression()
            self._take(":")
            return ("if", condition, when_true, self._expression())
        finally:
            self._depth -= 1

    def _binary(self, lowest: int) -> Tree:
        left = self._unary()
        while (op := self._peek()) in _BINARY and _BINARY[op] >= lowest:
            self._take()
            precedence = _BINARY[op]
            right = self._binary(precedence if op == "**" else precedence + 1)  # ** is right-associative
            left = ("binary", op, left, right)
        return left

    def _unary(self) -> Tree:
        op = self._peek()
        if op in ("-", "+", "~", "!"):
            self._take()
            self._depth += 1
            if self._depth > MAX_NESTING:
                raise FormulaError(f"nesting deeper than {MAX_NESTING} levels in {_excerpt(self._text)}")
            try:
                operand = self._unary()
                if self._peek() == "**":  # -x**2 is -(x**2)
                    self._take()
                    operand = ("binary", "**", operand, self._binary(_BINARY["**"]))
            finally:
                self._depth -= 1
            return ("unary", op, operand)
        return self._primary()

    def _primary(self) -> Tree:
        token = self._take()
        if token == "(":
            inner = self._expression()
            self._take(")")
            return inner
        if token[:2] in ("0x", "0X"):
            return ("num", int(token, 16))
        if token[0].isdigit() or token[0] == ".":
            return ("num", float(token) if any(c in token for c in ".eE") else int(token))
        if token[0].isalpha() or token[0] == "_":
            if self._peek() == "(":
                return self._call(token)
            if token in _CONSTANTS:
                return ("num", _CONSTANTS[token])
            return ("var", token)
        raise FormulaError(f"unexpected {token!r} where an operand belongs in {_excerpt(self._text)}")

    def _call(self, name: str) -> Tree:
        self._take("(")
        args = [self._expression()]
        while self._peek() == ",":
            self._take(",")
            args.append(self._expression())
        self._take(")")
        if name == "ROUND" and len(args) in (1, 2):
            return ("call", name, tuple(args))
        if name in _FUNCTIONS_1 and len(args) == 1:
            return ("call", name, tuple(args))
        raise FormulaError(f"unknown function {name} of {len(args)} argument(s) in {_excerpt(self._text)}")


def parse_formula(text: str) -> Tree:
    """Parse a GenApi formula into an evaluation tree.

    Parameters
    ----------
    text
        The formula as written in the XML (``Formula``, ``FormulaTo`` or ``FormulaFrom``).

    Returns
    -------
    tuple
        The tree; pass it to :func:`evaluate`.

    Raises
    ------
    FormulaError
        A syntax error, an unknown function, more than :data:`MAX_FORMULA_CHARS` characters or a
        nesting deeper than :data:`MAX_NESTING`.
    """
    return _Parser(text).parse()


def variables(tree: Tree) -> frozenset[str]:
    """The variable names a tree refers to (the node checks each is defined before any evaluation)."""
    found: set[str] = set()
    stack = [tree]
    while stack:
        node = stack.pop()
        kind = node[0]
        if kind == "var":
            found.add(node[1])
        elif kind == "unary":
            stack.append(node[2])
        elif kind == "binary":
            stack.extend(node[2:])
        elif kind == "if":
            stack.extend(node[1:])
        elif kind == "call":
            stack.extend(node[2])
    return frozenset(found)


def evaluate(tree: Tree, lookup: Callable[[str], Number], *, integer: bool) -> Number:
    """Evaluate a parsed formula.

    Parameters
    ----------
    tree
        From :func:`parse_formula`.
    lookup
        Called with a variable's name when (and only when) its value is needed.
    integer
        Signed 64-bit integer arithmetic (IntSwissKnife, IntConverter) instead of double precision.

    Returns
    -------
    int or float
        An int when ``integer`` (a float result is truncated towards zero); otherwise a float or int.
        Integer operands stay integers (wrapped to 64 bits) and a float operand makes the result
        float; so ``7 / 2`` is 3 in an integer formula and 3.5 in a float one.

    Raises
    ------
    FormulaError
        Division by zero, a shift count outside 0..63, a negative integer power, a math domain
        error or a non-finite result.
    """
    try:
        value = _Evaluation(lookup, integer).run(tree)
    except (ValueError, OverflowError, ZeroDivisionError) as exc:
        if isinstance(exc, FormulaError):
            raise
        raise FormulaError(f"cannot evaluate: {exc}") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise FormulaError(f"result {value} is not finite")
    return _wrap(math.trunc(value)) if integer else value


class _Evaluation:
    """One evaluation: integers stay integers (wrapped to 64 bits), a float operand makes a float."""

    def __init__(self, lookup: Callable[[str], Number], integer: bool) -> None:
        self._lookup = lookup
        self._integer = integer

    @staticmethod
    def _int(value: Number) -> int:
        if isinstance(value, float):
            if not math.isfinite(value):
                raise FormulaError(f"{value} has no integer value")
            return _wrap(math.trunc(value))
        return value

    def run(self, node: Tree) -> Number:
        kind = node[0]
        if kind == "num":
            return node[1]
        if kind == "var":
            value = self._lookup(node[1])
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise FormulaError(f"variable {node[1]} has the non-numeric value {value!r}")
            return value
        if kind == "if":
            return self.run(node[2]) if self.run(node[1]) else self.run(node[3])
        if kind == "unary":
            return self._unary(node[1], self.run(node[2]))
        if kind == "binary":
            op = node[1]
            if op == "&&":
                return int(bool(self.run(node[2])) and bool(self.run(node[3])))
            if op == "||":
                return int(bool(self.run(node[2])) or bool(self.run(node[3])))
            return self._binary(op, self.run(node[2]), self.run(node[3]))
        return self._call(node[1], [self.run(arg) for arg in node[2]])

    def _unary(self, op: str, a: Number) -> Number:
        if op == "-":
            return _wrap(-a) if isinstance(a, int) else -a
        if op == "+":
            return a
        if op == "~":
            return _wrap(~self._int(a))
        return int(not a)

    def _binary(self, op: str, a: Number, b: Number) -> Number:
        if op in ("=", "<>", "!=", "<", "<=", ">", ">="):
            return int({"=": a == b, "<>": a != b, "!=": a != b, "<": a < b, "<=": a <= b, ">": a > b,
                        ">=": a >= b}[op])
        if op in ("&", "|", "^", "<<", ">>"):
            return self._bitwise(op, self._int(a), self._int(b))
        if op in ("/", "%"):
            if b == 0:
                raise FormulaError(f"division by zero ({a} {op} 0)")
            if isinstance(a, int) and isinstance(b, int) and (self._integer or op == "%"):
                quotient = abs(a) // abs(b) * (1 if (a < 0) == (b < 0) else -1)  # C: towards zero
                return _wrap(quotient) if op == "/" else _wrap(a - quotient * b)
            return a / b if op == "/" else math.fmod(a, b)
        if op == "**":
            return self._power(a, b)
        result = a + b if op == "+" else a - b if op == "-" else a * b
        return _wrap(result) if isinstance(result, int) else result

    @staticmethod
    def _bitwise(op: str, a: int, b: int) -> int:
        if op in ("<<", ">>"):
            if not 0 <= b <= 63:
                raise FormulaError(f"shift count {b} outside 0..63")
            return _wrap(a << b) if op == "<<" else a >> b
        return _wrap(a & b if op == "&" else a | b if op == "|" else a ^ b)

    def _power(self, a: Number, b: Number) -> Number:
        if isinstance(a, int) and isinstance(b, int):
            if b < 0:
                if self._integer:
                    raise FormulaError(f"negative integer power ({a} ** {b})")
                return float(a) ** b
            if self._integer or b * a.bit_length() > 62:
                return _wrap(pow(a, b, _INT64)) if self._integer else float(a) ** b
            return a ** b  # exact while it fits
        return float(a) ** float(b)

    @staticmethod
    def _call(name: str, args: list[Number]) -> Number:
        if name == "ROUND":
            digits = _Evaluation._int(args[1]) if len(args) == 2 else 0
            if not -20 <= digits <= 20:
                raise FormulaError(f"ROUND to {digits} digits; expected -20..20")
            scale = 10.0 ** digits  # halves round away from zero, as C's round()
            rounded = math.copysign(math.floor(abs(float(args[0])) * scale + 0.5), args[0]) / scale
            return int(rounded) if digits <= 0 else rounded
        return _FUNCTIONS_1[name](args[0])
