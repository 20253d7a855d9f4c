"""GCS 2.0 framing on the controller's side: bytes in -> command lines and single-byte commands; answers out.

Rules (PI GCS 2.0, as PI's controller manuals state them, e.g. C-863.12 manual MS249E v1.2.1,
section 8.2 "GCS Syntax for Syntax Version 2.0", p. 115, and section 8.6, p. 127; E-871 manual
PZ285EN, "#5"/"#7", p. 118):

* a command line ends with LF; the mnemonic and every argument are separated by a space;
* single-character commands (``#5`` = 0x05 motion status, ``#7`` = 0x07 ready status, ``#24`` =
  0x18 stop all) are sent alone, without LF, and are acted on at once, also in the middle of a
  line the host is still sending (they are not part of it);
* an answer of several lines ends every line but the last with a space before the LF, so the
  host knows more follows (PI's own host library ends an answer at an LF not preceded by a space).

Choices where the documents are silent: a CR or tab before the LF is ignored (hosts that send
CRLF still work); a line longer than :data:`MAX_LINE` bytes is refused with error 3 (command too
long) when its LF arrives, never run cut short; an empty line is ignored.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from wavestack.simulators.pi_gcs.faults import ReplyFault

__all__ = ["Delivery", "LineAssembler", "MAX_LINE", "SINGLE_BYTE_COMMANDS", "deliver", "format_reply"]

#: Longest command line accepted, bytes (the controllers' buffer size is not documented).
MAX_LINE = 1024
#: Single-byte commands this controller knows: byte -> its GCS name.
SINGLE_BYTE_COMMANDS = {0x05: "#5", 0x07: "#7", 0x18: "#24"}


@dataclass(frozen=True)
class Delivery:
    """What goes back for one command: ``(delay_s, chunk)`` pieces (delay from the previous piece), then maybe a close."""

    pieces: tuple[tuple[float, bytes], ...] = ()
    close: bool = False


def format_reply(lines: Sequence[str]) -> bytes:
    """Encode an answer: every line but the last ends with ``" \\n"``, the last with ``"\\n"``.

    Examples
    --------
    >>> format_reply(["X=1", "Y=0"])
    b'X=1 \\nY=0\\n'
    """
    return (" \n".join(lines) + "\n").encode("latin-1")


def deliver(reply: bytes, fault: ReplyFault | None) -> Delivery:
    """How ``reply`` reaches the host under a split or truncate ``fault`` (None: at once, whole)."""
    if not reply:
        return Delivery()
    if fault is None:
        return Delivery(((0.0, reply),))
    if fault.kind == "truncate":
        return Delivery(((0.0, reply[:fault.keep_bytes]),) if fault.keep_bytes else ())
    if fault.kind == "split":
        pieces = max(1, min(fault.pieces, len(reply)))
        cuts = [round(i * len(reply) / pieces) for i in range(pieces + 1)]
        return Delivery(tuple((0.0 if i == 0 else fault.gap_s, reply[cuts[i]:cuts[i + 1]]) for i in range(pieces)))
    return Delivery(((0.0, reply),))


class LineAssembler:
    """Cuts the host's byte stream into events, whatever the packet boundaries.

    :meth:`feed` returns, in arrival order, ``("line", text)`` for each complete line (LF removed,
    decoded as Latin-1), ``("single", name)`` for each single-byte command, and ``("too_long", "")``
    for a line that overflowed :data:`MAX_LINE`.

    Examples
    --------
    >>> assembler = LineAssembler()
    >>> assembler.feed(b"POS?\\nMO"), assembler.feed(b"V X 1\\x05\\n")
    ([('line', 'POS?')], [('single', '#5'), ('line', 'MOV X 1')])
    """

    def __init__(self) -> None:
        self._line = bytearray()
        self._overflow = False

    def feed(self, data: bytes) -> list[tuple[str, str]]:
        """Events completed by ``data`` (see the class docstring)."""
        events: list[tuple[str, str]] = []
        for byte in data:
            if byte in SINGLE_BYTE_COMMANDS:
                events.append(("single", SINGLE_BYTE_COMMANDS[byte]))
            elif byte == 0x0A:
                if self._overflow:
                    events.append(("too_long", ""))
                else:
                    events.append(("line", self._line.decode("latin-1")))
                self._line.clear()
                self._overflow = False
            elif len(self._line) < MAX_LINE:
                self._line.append(byte)
            else:
                self._overflow = True
        return events
