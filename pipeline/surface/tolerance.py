"""The drawing's surface form tolerance, ISO 10110-5 notation ``3/A(B/C)``, read or refused.

Grammar accepted (white space anywhere, case-insensitive keywords, ``λ`` or ``lambda``)::

    3/A                          sagitta error only
    3/A(B)                       and irregularity
    3/A(B/C)                     and rotationally symmetric irregularity
    3/A(B/C; RMSx < D; ...)      and one or more RMS limits, x one of t, i, a
    ... ; lambda = 632.8 nm      the test wavelength (after the closing parenthesis, or
                                 as the last clause inside it)

``A`` is the sagitta error (SAG), ``B`` the irregularity (IRR), ``C`` the rotationally
symmetric irregularity (RSI), ``D`` an RMS limit (RMSt total, RMSi irregularity, RMSa
non-rotationally-symmetric irregularity). Each is a number of fringe spacings (one fringe is
half the test wavelength of surface height) at 546.07 nm unless a wavelength is stated, or a
number followed by ``nm``; ``-`` leaves it unspecified. Limits are the largest allowed value:
``A`` bounds the magnitude of the (signed) sagitta error, the others their non-negative figures;
``RMSx < D`` is read as ``RMSx <= D``.

The definitions of the quantities (ISO 14999-4) live in :mod:`.form`; this module only reads
the notation. Sources: ISO 10110-5:2015 (public preview) and the public summaries of ISO 14999-4;
the parts of the standard that are not public (e.g. signed sagitta tolerances) are refused with
the reason rather than guessed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .fringes import DEFAULT_TEST_WAVELENGTH_NM, fringe_nm

__all__ = ["FORM_QUANTITIES", "FormTolerance", "ToleranceError", "parse_form_tolerance"]

#: The quantities a form tolerance can limit, in the drawing's order.
FORM_QUANTITIES = ("SAG", "IRR", "RSI", "RMSt", "RMSi", "RMSa")

_NUMBER = r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_VALUE = re.compile(rf"\s*(?:(-)(?![\d.])|({_NUMBER})\s*(nm)?)", re.IGNORECASE)
_RMS = re.compile(rf"\s*RMS([tia])\s*(<=|<|≤)\s*({_NUMBER})\s*(nm)?\s*", re.IGNORECASE)
_WAVELENGTH = re.compile(rf"\s*(?:λ|lambda)\s*=\s*({_NUMBER})\s*(nm)?\s*", re.IGNORECASE)
_WAVELENGTH_RANGE_NM = (100.0, 20000.0)  # UV to thermal infrared: the wavelengths interferometers test at


class ToleranceError(ValueError):
    """A tolerance that cannot be read: the message quotes it, says where and what was expected."""


@dataclass(frozen=True)
class FormTolerance:
    """A surface form tolerance in fringe spacings at ``wavelength_nm``.

    Attributes
    ----------
    notation : str
        The text as written on the drawing.
    wavelength_nm : float
        The test wavelength the fringes refer to (546.07 nm unless stated).
    sag, irr, rsi : float or None
        Largest |SAG|, IRR and RSI in fringes; None where the drawing says ``-`` or nothing.
    rmst, rmsi, rmsa : float or None
        Largest RMSt, RMSi, RMSa in fringes; None where not specified.

    Examples
    --------
    >>> t = parse_form_tolerance("3/2(0.5/0.2)")
    >>> t.sag, t.irr, t.rsi, t.wavelength_nm
    (2.0, 0.5, 0.2, 546.07)
    >>> round(t.limits_nm()["IRR"], 4)
    136.5175
    """

    notation: str
    wavelength_nm: float = DEFAULT_TEST_WAVELENGTH_NM
    sag: float | None = None
    irr: float | None = None
    rsi: float | None = None
    rmst: float | None = None
    rmsi: float | None = None
    rmsa: float | None = None

    def limits(self) -> dict[str, float]:
        """The specified limits in fringes, by quantity name (``FORM_QUANTITIES`` order)."""
        values = (self.sag, self.irr, self.rsi, self.rmst, self.rmsi, self.rmsa)
        return {name: value for name, value in zip(FORM_QUANTITIES, values) if value is not None}

    def limits_nm(self) -> dict[str, float]:
        """The specified limits in nanometres of surface height."""
        scale = fringe_nm(self.wavelength_nm)
        return {name: value * scale for name, value in self.limits().items()}

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form: the notation, the wavelength, and each limit in fringes and nm."""
        scale = fringe_nm(self.wavelength_nm)
        return {"notation": self.notation, "wavelength_nm": self.wavelength_nm,
                "limits_fringes": self.limits(),
                "limits_nm": {name: value * scale for name, value in self.limits().items()}}


class _Reader:
    """A cursor over the notation that raises :class:`ToleranceError` naming the position."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.at = 0

    def fail(self, expected: str) -> ToleranceError:
        rest = self.text[self.at:].strip()
        found = f"got {rest[:12]!r}" if rest else "got the end of the text"
        return ToleranceError(f"tolerance {self.text!r}: at character {self.at + 1}, expected {expected}; {found}")

    def skip_space(self) -> None:
        while self.at < len(self.text) and self.text[self.at].isspace():
            self.at += 1

    def take(self, literal: str) -> bool:
        self.skip_space()
        if self.text.startswith(literal, self.at):
            self.at += len(literal)
            return True
        return False

    def match(self, pattern: re.Pattern[str]) -> re.Match[str] | None:
        found = pattern.match(self.text, self.at)
        if found is not None:
            self.at = found.end()
        return found

    def at_end(self) -> bool:
        self.skip_space()
        return self.at == len(self.text)


@dataclass(frozen=True)
class _Written:
    """A limit as written: a number in fringes or in nm (converted once the wavelength is known)."""

    value: float
    in_nm: bool


def parse_form_tolerance(text: str) -> FormTolerance:
    """Read a surface form tolerance in ISO 10110-5 notation.

    Parameters
    ----------
    text : str
        E.g. ``"3/2(0.5/0.2)"``, ``"3/-(-/-; RMSi < 0.05)"``, ``"3/1(0.25) λ = 632.8 nm"``.

    Returns
    -------
    FormTolerance
        Limits in fringes at the stated wavelength (546.07 nm when none is stated); values
        written in nm are converted at that wavelength.

    Raises
    ------
    ToleranceError
        For anything it cannot read, naming the text, the character where reading stopped and
        what was expected there; also for a tolerance that limits nothing, a limit <= 0, a
        quantity given twice, and a wavelength outside 100 nm to 20 um.

    Examples
    --------
    >>> parse_form_tolerance("3/-(-/-; RMSi < 0.05)").rmsi
    0.05
    >>> parse_form_tolerance("3/2(x)")
    Traceback (most recent call last):
    ...
    wavestack.pipeline.surface.tolerance.ToleranceError: tolerance '3/2(x)': at character 5, expected the irregularity (IRR): a number > 0, a number with 'nm', or '-'; got 'x)'
    """
    if not isinstance(text, str):
        raise ToleranceError(f"tolerance {text!r}: expected text such as '3/2(0.5/0.2)'")
    reader = _Reader(text.replace("\u2212", "-"))
    if not (reader.take("3") and reader.take("/")):
        reader.at = 0
        raise reader.fail("the surface form code '3/' (ISO 10110-5), e.g. '3/2(0.5/0.2)'")
    written: dict[str, _Written | None] = {"SAG": _value(reader, "the sagitta error (SAG)")}
    if reader.take("("):
        written["IRR"] = _value(reader, "the irregularity (IRR)")
        if reader.take("/"):
            written["RSI"] = _value(reader, "the rotationally symmetric irregularity (RSI)")
        wavelength = _clauses(reader, written)
        if not reader.take(")"):
            raise reader.fail("')' closing the tolerance, ';' before an RMS limit, or '/' before RSI")
    else:
        wavelength = None
    if reader.take(";") or reader.take(","):
        pass
    if wavelength is None and not reader.at_end():
        found = reader.match(_WAVELENGTH)
        if found is None:
            raise reader.fail("the end of the tolerance or a wavelength such as 'lambda = 632.8 nm'")
        wavelength = _wavelength(reader, found)
    if not reader.at_end():
        raise reader.fail("the end of the tolerance")
    return _tolerance(text, written, DEFAULT_TEST_WAVELENGTH_NM if wavelength is None else wavelength)


def _value(reader: _Reader, what: str) -> _Written | None:
    """A number (fringes), a number with 'nm', or '-' (None)."""
    found = reader.match(_VALUE)
    if found is None:
        raise reader.fail(f"{what}: a number > 0, a number with 'nm', or '-'")
    if found.group(1):
        return None
    value = float(found.group(2))
    if not value > 0:
        reader.at = found.start()
        reader.skip_space()
        raise reader.fail(f"{what}: a number > 0 (a zero tolerance cannot be met), a number with 'nm', or '-'")
    return _Written(value, bool(found.group(3)))


def _clauses(reader: _Reader, written: dict[str, _Written | None]) -> float | None:
    """The ``; RMSx < D`` clauses and an optional wavelength inside the parentheses."""
    wavelength = None
    while reader.take(";"):
        found = reader.match(_RMS)
        if found is not None:
            name = "RMS" + found.group(1).lower()
            if name in written:
                reader.at = found.start()
                reader.skip_space()
                raise reader.fail(f"each quantity once, but {name} is given again")
            value = float(found.group(3))
            if not value > 0:
                reader.at = found.start()
                reader.skip_space()
                raise reader.fail(f"{name}: a limit > 0")
            written[name] = _Written(value, bool(found.group(4)))
            continue
        found = reader.match(_WAVELENGTH)
        if found is None or wavelength is not None:
            raise reader.fail("an RMS limit such as 'RMSi < 0.05' (x one of t, i, a) or 'lambda = 632.8 nm'")
        wavelength = _wavelength(reader, found)
    return wavelength


def _wavelength(reader: _Reader, found: re.Match[str]) -> float:
    value = float(found.group(1))
    low, high = _WAVELENGTH_RANGE_NM
    if not low <= value <= high:
        reader.at = found.start(1)
        raise reader.fail(f"a test wavelength in nm between {low:g} and {high:g}")
    return value


def _tolerance(text: str, written: dict[str, _Written | None], wavelength_nm: float) -> FormTolerance:
    scale = fringe_nm(wavelength_nm)
    fringes = {name: None if value is None else value.value / scale if value.in_nm else value.value
               for name, value in written.items()}
    if not any(value is not None for value in fringes.values()):
        raise ToleranceError(f"tolerance {text!r}: every quantity is '-', so nothing is toleranced; "
                             "expected at least one limit, e.g. '3/2(0.5/0.2)'")
    return FormTolerance(notation=text.strip(), wavelength_nm=wavelength_nm, sag=fringes.get("SAG"),
                         irr=fringes.get("IRR"), rsi=fringes.get("RSI"), rmst=fringes.get("RMSt"),
                         rmsi=fringes.get("RMSi"), rmsa=fringes.get("RMSa"))
