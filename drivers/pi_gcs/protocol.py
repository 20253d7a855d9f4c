"""PI GCS 2.0 ASCII protocol, pure: encode commands, frame and parse replies (no I/O).

The wire rules this module implements, and where they come from:

- A command is ASCII, a mnemonic and space-separated arguments, ended by one LF; several commands
  may follow each other in one write (the controller buffers and splits them at the LFs). PI's
  own library sends a command and ``ERR?`` in one write ([2]_, ``GCSMessages.send`` with
  ``embederr``).
- A reply ends at the first LF that is *not* preceded by a space: in a multi-line reply every line
  but the last ends with a space before its LF ([2]_, ``gcsmessages.eol`` and ``_check_no_eol``;
  C-887 manual [1]_, "GCS syntax"). :func:`reply_end` finds that LF.
- Axis values are answered one per line as ``AXIS=value`` (``POS?``, ``ONT?``, ``TMN?``, ``TMX?``,
  ``SVO?``, ``FRF?``, ``SPI?``); PI's EPICS driver also accepts spaces around ``=`` [3]_.
- Single-byte commands go without LF and are answered at once: ``#5`` (0x05) answers the motion
  status as a hexadecimal bit mask, bit i set while the i-th axis of ``SAI? ALL`` moves ([2]_,
  ``IsMoving``: ``int(answer, 16)``); ``#7`` (0x07) answers the byte 0xB1 when the controller is
  ready, 0xB0 when busy, then LF ([2]_, ``IsControllerReady``: 177 / 176); ``#24`` (0x18) stops
  all motion, answers nothing, and sets error 10 ([2]_, ``StopAll``).
- ``ERR?`` answers the last error code and resets it to 0; ``CSV?`` answers the GCS syntax
  version, ``2.0`` for this protocol; ``VLS?`` answers the platform velocity as one number [3]_.
- Pivot coordinates are called R, S, T; X, Y, Z are accepted as aliases (PI MATLAB library,
  ``SPI``); :func:`encode_command` is given whichever names the caller chooses.

Numbers are written in fixed point with at most 9 decimals (1 pm in mm, 1e-9 deg): never in
exponent notation, whose acceptance the GCS documentation does not promise.
:func:`quantize` gives the value the controller will actually receive, so that limit checks
are done on it.

References
----------
.. [1] Physik Instrumente, MS204E, "C-887 Hexapod Controller User Manual" (GCS commands, syntax).
.. [2] Physik Instrumente, PIPython, ``pipython/pidevice/gcsmessages.py`` and
   ``pipython/pidevice/gcs2/gcs2commands.py``.
.. [3] epics-modules/motor, ``motorApp/PIGCS2Src/PIGCS2_HexapodController.cpp`` (``VLS?``) and
   ``PIHexapodController.cpp`` (``#5``, ``#24``, ``SPI?`` lines ``R = 1.0``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Final

from wavestack.drivers.errors import ProtocolError

__all__ = [
    "BUSY", "LF", "MOTION_STATUS", "READY", "READY_STATUS", "STOP_ALL", "check_axis_id", "encode_command",
    "encode_axis_values", "format_number", "parse_axes", "parse_axis_flags", "parse_axis_values",
    "parse_error_code", "parse_motion_mask", "parse_number", "parse_ready", "quantize", "reply_end",
    "split_reply",
]

LF: Final = b"\n"
MOTION_STATUS: Final = b"\x05"  #: ``#5``
READY_STATUS: Final = b"\x07"  #: ``#7``
STOP_ALL: Final = b"\x18"  #: ``#24``
READY: Final = 0xB1  #: ``#7`` answer: ready
BUSY: Final = 0xB0  #: ``#7`` answer: busy

_DECIMALS: Final = 9
_AXIS_ID = re.compile(r"[A-Za-z0-9_]{1,16}")
_MNEMONIC = re.compile(r"[*A-Z][A-Z0-9]{0,7}\??")
_PAIR = re.compile(r"^\s*([A-Za-z0-9_]+)\s*=\s*(\S+)\s*$")
_HEX = re.compile(r"(0[xX])?[0-9A-Fa-f]{1,16}")


def check_axis_id(axis: str) -> str:
    """``axis`` if it is a GCS axis identifier (1-16 letters, digits or ``_``), else ValueError."""
    if not isinstance(axis, str) or not _AXIS_ID.fullmatch(axis):
        raise ValueError(f"GCS axis identifier must be 1-16 letters, digits or '_', got {axis!r}")
    return axis


def format_number(value: float) -> str:
    """A finite number as the controller reads it: fixed point, at most 9 decimals, no exponent.

    Examples
    --------
    >>> format_number(1.5), format_number(-0.0000000001), format_number(2), format_number(1e-9)
    ('1.5', '0', '2', '0.000000001')
    """
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"GCS arguments must be finite numbers, got {value!r}")
    text = f"{number:.{_DECIMALS}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def quantize(value: float) -> float:
    """The value the controller receives for ``value`` (what :func:`format_number` writes)."""
    return float(format_number(value))


def encode_command(mnemonic: str, *args: str | float | bool) -> bytes:
    """One GCS command line: mnemonic, arguments separated by single spaces, LF.

    Parameters
    ----------
    mnemonic
        ``MOV``, ``POS?``, ``*IDN?``, ... (upper case, optional trailing ``?``).
    args
        Axis identifiers (str, checked by :func:`check_axis_id`), numbers (:func:`format_number`)
        or booleans (``1`` / ``0``).

    Examples
    --------
    >>> encode_command("MOV", "X", 1.5, "Z", -0.25)
    b'MOV X 1.5 Z -0.25\\n'
    >>> encode_command("SVO", "X", True)
    b'SVO X 1\\n'
    """
    if not _MNEMONIC.fullmatch(mnemonic):
        raise ValueError(f"GCS mnemonic must be 1-8 upper-case letters or digits (optional '*' and '?'), "
                         f"got {mnemonic!r}")
    words = [mnemonic]
    for arg in args:
        if isinstance(arg, bool):
            words.append("1" if arg else "0")
        elif isinstance(arg, str):
            words.append(check_axis_id(arg))
        else:
            words.append(format_number(arg))
    return (" ".join(words)).encode("ascii") + LF


def encode_axis_values(mnemonic: str, values: Mapping[str, float | bool]) -> bytes:
    """``MNEMONIC AXIS value AXIS value ...`` in the mapping's order (``MOV``, ``SVO``, ``SPI``)."""
    if not values:
        raise ValueError(f"{mnemonic} needs at least one axis value")
    args: list[str | float | bool] = []
    for axis, value in values.items():
        args += [axis, value]
    return encode_command(mnemonic, *args)


def reply_end(buffer: bytes) -> int | None:
    """Length of the first complete reply in ``buffer`` (through its final LF), or None.

    The reply ends at the first LF not preceded by a space (an LF at the very start ends an empty
    reply).

    Examples
    --------
    >>> reply_end(b"X=1 \\nY=2\\nrest"), reply_end(b"X=1 \\n"), reply_end(b"\\n")
    (9, None, 1)
    """
    start = 0
    while True:
        at = buffer.find(LF, start)
        if at < 0:
            return None
        if at == 0 or buffer[at - 1:at] != b" ":
            return at + 1
        start = at + 1


def split_reply(buffer: bytes, *, device: str) -> tuple[list[str] | None, bytes]:
    """The first complete reply as its lines (continuation space and LF removed), and the rest.

    Returns ``(None, buffer)`` while no reply is complete.

    Raises
    ------
    ProtocolError
        The reply holds a byte outside printable ASCII (a ``#7`` answer is read with
        :func:`parse_ready` instead).

    Examples
    --------
    >>> split_reply(b"X=1 \\nY=2\\nZ", device="hexapod")
    (['X=1', 'Y=2'], b'Z')
    """
    end = reply_end(buffer)
    if end is None:
        return None, buffer
    raw, rest = buffer[:end], buffer[end:]
    if any(not (32 <= byte < 127) for byte in raw[:-1].replace(b" \n", b"")):
        raise ProtocolError(device, f"reply {raw[:60]!r} holds bytes outside printable ASCII; expected GCS text")
    lines = raw[:-1].decode("ascii").split(" \n")
    return lines, rest


def _single(lines: Sequence[str], device: str, what: str) -> str:
    if len(lines) != 1 or not lines[0].strip():
        raise ProtocolError(device, f"{what}: expected one value on one line, got {list(lines)[:6]!r}")
    return lines[0].strip()


def parse_number(lines: Sequence[str], *, device: str, what: str = "reply") -> float:
    """A reply of one finite number (``VLS?``, ``CSV?``); ProtocolError otherwise."""
    text = _single(lines, device, what)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ProtocolError(device, f"{what}: expected a finite number, got {text!r}")
    return value


def parse_error_code(lines: Sequence[str], *, device: str) -> int:
    """The ``ERR?`` reply: one integer (0 when no error).

    Examples
    --------
    >>> parse_error_code(["10"], device="hexapod")
    10
    """
    text = _single(lines, device, "ERR?")
    if not re.fullmatch(r"-?\d{1,9}", text):
        raise ProtocolError(device, f"ERR?: expected an integer error code, got {text!r}")
    return int(text)


def parse_axes(lines: Sequence[str], *, device: str) -> tuple[str, ...]:
    """The ``SAI?`` reply: one axis identifier per line, in the controller's order."""
    axes = tuple(line.strip() for line in lines)
    bad = [axis for axis in axes if not _AXIS_ID.fullmatch(axis)]
    if not axes or bad or len(set(axes)) != len(axes):
        raise ProtocolError(device, f"SAI?: expected distinct axis identifiers one per line, got {list(lines)[:8]!r}")
    return axes


def parse_axis_values(lines: Sequence[str], *, device: str, what: str) -> dict[str, float]:
    """``AXIS=value`` lines as ``{axis: value}`` (finite floats, each axis once).

    Examples
    --------
    >>> parse_axis_values(["X=1.5", "Y = -2"], device="hexapod", what="POS?")
    {'X': 1.5, 'Y': -2.0}
    """
    values: dict[str, float] = {}
    for line in lines:
        match = _PAIR.fullmatch(line)
        number = math.nan
        if match:
            try:
                number = float(match.group(2))
            except ValueError:
                pass
        if not match or not math.isfinite(number) or match.group(1) in values:
            raise ProtocolError(device, f"{what}: expected one 'AXIS=number' per line, each axis once, "
                                f"got line {line!r}")
        values[match.group(1)] = number
    return values


def parse_axis_flags(lines: Sequence[str], *, device: str, what: str) -> dict[str, bool]:
    """``AXIS=0|1`` lines (``ONT?``, ``SVO?``, ``FRF?``) as ``{axis: bool}``."""
    values = parse_axis_values(lines, device=device, what=what)
    bad = {axis: value for axis, value in values.items() if value not in (0.0, 1.0)}
    if bad:
        raise ProtocolError(device, f"{what}: expected 0 or 1 per axis, got {bad}")
    return {axis: value == 1.0 for axis, value in values.items()}


def parse_motion_mask(lines: Sequence[str], all_axes: Sequence[str], *, device: str) -> dict[str, bool]:
    """The ``#5`` reply (hexadecimal bit mask; bit i = ``all_axes[i]``) as ``{axis: moving}``.

    ``all_axes`` is the controller's axis order (``SAI? ALL``; on a hexapod its first axes are
    those of ``SAI?``, X Y Z U V W); bits beyond it are ignored.

    Examples
    --------
    >>> parse_motion_mask(["5"], ("X", "Y", "Z"), device="hexapod")
    {'X': True, 'Y': False, 'Z': True}
    """
    text = _single(lines, device, "#5")
    if not _HEX.fullmatch(text):
        raise ProtocolError(device, f"#5: expected a hexadecimal motion mask, got {text!r}")
    mask = int(text, 16)  # bits above len(all_axes) belong to axes the caller did not list: ignored
    return {axis: bool(mask >> i & 1) for i, axis in enumerate(all_axes)}


def parse_ready(reply: bytes, *, device: str) -> bool:
    """The ``#7`` reply (0xB1 ready / 0xB0 busy, then LF) as True (ready) or False (busy).

    Examples
    --------
    >>> parse_ready(bytes([0xB1]) + LF, device="hexapod"), parse_ready(bytes([0xB0]) + LF, device="hexapod")
    (True, False)
    """
    if len(reply) != 2 or reply[1:] != LF or reply[0] not in (READY, BUSY):
        raise ProtocolError(device, f"#7: expected 0xB1 or 0xB0 then LF, got {reply!r}")
    return reply[0] == READY
