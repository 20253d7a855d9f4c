"""The result display block: what the machine's operator panel shows of each measurement (pure).

The host writes it once per cycle, whole, in one FC16 request, on the connection that owns the
PLC (as the heartbeat); any Modbus client (the PLC's own HMI, a SCADA) may read it. It carries no
command: nothing on the machine moves on it.

Layout (8 registers; float32 in the block's byte order):

========  ========  ===================================================================
register  type      meaning
========  ========  ===================================================================
0         uint16    result counter: the station's result index, mod 65536 (changes every cycle)
1         uint16    flags: bit 0 result valid, bit 1 surface figures measured
2-3       float32   residual RMS of the fit, nm of surface (0 when the result is invalid)
4-5       float32   PVr (Evans' robust PV), nm of surface (0 unless bit 1 is set)
6         uint16    spec verdict (:class:`SpecCode`): 0 no spec, 1 pass, 2 fail, 3 not judged
7         uint16    limiting quantity (:data:`LIMITING_QUANTITIES`): 0 none, 1 SAG, 2 IRR, 3 RSI,
                    4 RMSt, 5 RMSi, 6 RMSa (ISO 10110-5 / ISO 14999-4 form quantities)
========  ========  ===================================================================

"Not judged" is a station with a drawing tolerance whose result has no figures to judge (an
invalid result, an aperture too small for the figures): a panel must not show it as "no spec".
The limiting quantity is the one with the largest figure-to-limit ratio, on a pass as on a fail.

Examples
--------
>>> display = ResultDisplay(result_index=12, valid=True, residual_rms_nm=3.5, pvr_nm=41.0,
...                         spec=SpecCode.FAIL, limiting="IRR")
>>> words = encode_display(display, "ABCD")
>>> words[0], words[1], words[6], words[7]
(12, 3, 2, 2)
>>> decode_display(words, "ABCD") == display
True
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from wavestack.drivers.plc.codec import WordOrder, decode_float32, encode_float32

__all__ = ["DISPLAY_BLOCK_COUNT", "LIMITING_QUANTITIES", "ResultDisplay", "SpecCode", "decode_display",
           "encode_display", "invalid_display"]

#: Registers of the display block.
DISPLAY_BLOCK_COUNT = 8
#: The limiting quantity's code is its index here (0: none).
LIMITING_QUANTITIES = ("", "SAG", "IRR", "RSI", "RMSt", "RMSi", "RMSa")

_VALID, _FIGURES = 1, 2


class SpecCode(enum.IntEnum):
    """The drawing's verdict on one result, as the display block carries it."""

    NO_SPEC = 0
    PASS = 1
    FAIL = 2
    NOT_JUDGED = 3


@dataclass(frozen=True)
class ResultDisplay:
    """One result as the machine's panel shows it.

    Attributes
    ----------
    result_index : int
        The station's result index (>= 0; the block carries it mod 65536).
    valid : bool
        The result can be trusted.
    residual_rms_nm : float
        The fit's residual RMS, nm of surface, finite and >= 0 (0 for an invalid result).
    pvr_nm : float or None
        Evans' PVr, nm of surface; None when the result has no surface figures.
    spec : SpecCode
    limiting : str
        The limiting quantity's name (one of :data:`LIMITING_QUANTITIES`; ``""`` without a verdict).

    Raises
    ------
    ValueError
        A negative index, a non-finite or negative figure, an unknown quantity, or a verdict
        (pass/fail) without a limiting quantity, or a limiting quantity without one.
    """

    result_index: int
    valid: bool
    residual_rms_nm: float
    pvr_nm: float | None
    spec: SpecCode
    limiting: str = ""

    def __post_init__(self) -> None:
        if self.result_index < 0:
            raise ValueError(f"result_index must be >= 0, got {self.result_index}")
        for name, value in (("residual_rms_nm", self.residual_rms_nm), ("pvr_nm", self.pvr_nm)):
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0 nm, got {value!r}")
        if self.limiting not in LIMITING_QUANTITIES:
            raise ValueError(f"limiting quantity {self.limiting!r} is none of {', '.join(LIMITING_QUANTITIES[1:])}")
        if (self.spec in (SpecCode.PASS, SpecCode.FAIL)) != bool(self.limiting):
            raise ValueError(f"a {self.spec.name} verdict {'needs' if self.limiting == '' else 'has no'} "
                             f"limiting quantity, got {self.limiting!r}")


def invalid_display(result_index: int, *, has_spec: bool) -> ResultDisplay:
    """The display of a result that cannot be trusted: invalid, no figures, the verdict not judged."""
    return ResultDisplay(result_index, False, 0.0, None, SpecCode.NOT_JUDGED if has_spec else SpecCode.NO_SPEC)


def encode_display(display: ResultDisplay, order: WordOrder) -> list[int]:
    """The display block's :data:`DISPLAY_BLOCK_COUNT` registers (layout in the module notes).

    Raises
    ------
    ValueError
        A figure beyond the float32 range, or an unknown byte order.
    """
    flags = (_VALID if display.valid else 0) | (_FIGURES if display.pvr_nm is not None else 0)
    return [display.result_index & 0xFFFF, flags,
            *encode_float32(display.residual_rms_nm if display.valid else 0.0, order),
            *encode_float32(display.pvr_nm if display.pvr_nm is not None else 0.0, order),
            int(display.spec), LIMITING_QUANTITIES.index(display.limiting)]


def decode_display(registers: list[int], order: WordOrder) -> ResultDisplay:
    """The display block read back (figures rounded to float32, the index mod 65536).

    Raises
    ------
    ValueError
        Not :data:`DISPLAY_BLOCK_COUNT` registers, an unknown verdict or quantity code.
    """
    if len(registers) != DISPLAY_BLOCK_COUNT:
        raise ValueError(f"display block: expected {DISPLAY_BLOCK_COUNT} registers, got {len(registers)}")
    index, flags, *floats = registers[:6]
    if registers[7] >= len(LIMITING_QUANTITIES):
        raise ValueError(f"display block: limiting quantity code {registers[7]} is not in the code table")
    pvr = decode_float32((floats[2], floats[3]), order)
    return ResultDisplay(result_index=index, valid=bool(flags & _VALID),
                         residual_rms_nm=decode_float32((floats[0], floats[1]), order),
                         pvr_nm=pvr if flags & _FIGURES else None, spec=SpecCode(registers[6]),
                         limiting=LIMITING_QUANTITIES[registers[7]])

