"""The two command sets of the MDT693B / MDT694B and the MDT693A: which command does what (pure).

An MDT693B / MDT694B speaks its own command set (``xvoltage=``, ``xvoltage?``, ``vlimit?``, prompt
``>`` on firmware 1.10) until its MDT693A compatibility mode is switched on; from then on it speaks
the single-letter command set of the older MDT693A (prompt ``*``), which existing host software
uses. A real MDT693A speaks only the latter. :class:`CommandSet` holds each set as data, so the
driver asks ``commands.voltage_query("x")`` and never spells a command itself.

Sources, and the readings taken where they leave room (the conservative one each time):

* ``cm?`` / ``cm=``: the MDT693B firmware 1.10 built-in help (the list its ``?`` command prints, the
  "Command list" of the Thorlabs MDT693B/MDT694B manual) reads "CM? Gets MDT693A compatibility mode
  (0=Off, 1=On)" and "CM= Sets MDT693A compatibility mode (0=Off, 1=On)" (the MDT694B says
  "MDT694A"). A public session log of firmware 1.05 shows the words, not the digit, in the reply:
  ``*[MDT693A Compatibility Mode Off]``. :func:`parse_compatibility_mode` accepts both.
* The MDT693A command set (Thorlabs MDT693A operating manual, section on the computer interface;
  the manual itself was not reachable through our documentation search, so the names below are the
  ones public host programs written against it use, checked against logs of a real MDT693A with
  firmware 3.01): ``I`` product information (the same ``Model ...`` lines as ``id?``), ``XR?`` /
  ``YR?`` / ``ZR?`` read an output voltage (``[  12.3]``), ``XV<volts>`` / ``YV`` / ``ZV`` set one,
  ``XL?`` / ``XH?`` (and ``Y``, ``Z``) read the lower and upper output limit, ``%`` reads the
  front-panel limit switch. Prompt ``*``; a command the unit does not know answers ``!`` instead.
  Conservative readings: no ``=`` between command and value (none of the sources writes one), at
  most two decimals, and no reliance on the echo command (``E``), whose argument the sources do not
  agree on: the driver accepts an echo instead of switching it off, compared without regard to case
  because the real MDT693A echoes in lower case.
* Whether a unit in compatibility mode still accepts the MDT693B's long commands is not documented;
  the driver therefore uses only the MDT693A set in that mode (which also suits a real MDT693A), and
  the simulator refuses long commands there.

Examples
--------
>>> A_COMMANDS.voltage_query("y")
'YR?'
>>> A_COMMANDS.set_voltage("x", 12.345)
b'XV12.35\\r'
>>> B_COMMANDS.set_voltage("x", 12.345)
b'xvoltage=12.35\\r'
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.mdt693b.protocol import (
    AXES,
    Reply,
    encode_command,
    encode_query,
    encode_set_voltage,
)

__all__ = ["A_COMMANDS", "B_COMMANDS", "COMMAND_SETS", "CommandSet", "CommandSetName",
           "command_set_after_probe", "encode_compatibility_mode", "parse_compatibility_mode"]

CommandSetName = Literal["mdt693b", "mdt693a"]

_ON_OFF = re.compile(r"\b(on|off)\b", re.IGNORECASE)
_DIGIT = re.compile(r"^\s*\[?\s*([01])\s*\]?\s*$")


@dataclass(frozen=True)
class CommandSet:
    """One command set: the text of each command the driver uses.

    Attributes
    ----------
    name
        ``"mdt693b"`` (the B firmware's own) or ``"mdt693a"`` (the MDT693A's, also the B's
        compatibility mode).
    id_query, vlimit_query
        Identity (``id?`` / ``I``) and limit switch (``vlimit?`` / ``%``) queries.
    """

    name: CommandSetName
    id_query: str
    vlimit_query: str

    def voltage_query(self, axis: str) -> str:
        """Read the output of ``axis``: ``xvoltage?`` or ``XR?``."""
        return self._axis_query(axis, "voltage", "R")

    def min_query(self, axis: str) -> str:
        """Read the lower output limit of ``axis``: ``xmin?`` or ``XL?``."""
        return self._axis_query(axis, "min", "L")

    def max_query(self, axis: str) -> str:
        """Read the upper output limit of ``axis``: ``xmax?`` or ``XH?``."""
        return self._axis_query(axis, "max", "H")

    def set_voltage(self, axis: str, volts: float) -> bytes:
        """Encode a setpoint with two decimals: ``xvoltage=12.35`` or ``XV12.35``.

        Raises
        ------
        ValueError
            Unknown axis, or a non-finite or negative voltage.
        """
        encoded = encode_set_voltage(axis, volts)  # validates; the B form
        if self.name == "mdt693b":
            return encoded
        value = encoded.split(b"=", 1)[1]
        return axis.upper().encode("ascii") + b"V" + value

    def _axis_query(self, axis: str, quantity: str, letter: str) -> str:
        if self.name == "mdt693b":
            return encode_query(axis, quantity).rstrip(b"\r").decode("ascii")
        if axis not in AXES:
            raise ValueError(f"axis must be one of {AXES}, got {axis!r}")
        return f"{axis.upper()}{letter}?"


B_COMMANDS = CommandSet("mdt693b", id_query="id?", vlimit_query="vlimit?")
A_COMMANDS = CommandSet("mdt693a", id_query="I", vlimit_query="%")
COMMAND_SETS: dict[str, CommandSet] = {"mdt693b": B_COMMANDS, "mdt693a": A_COMMANDS}


def encode_compatibility_mode(on: bool) -> bytes:
    """``cm=1`` (MDT693A command set) or ``cm=0`` (the unit's own).

    Examples
    --------
    >>> encode_compatibility_mode(True)
    b'cm=1\\r'
    """
    return encode_command(f"cm={1 if on else 0}")


def parse_compatibility_mode(body: str, *, device: str = "MDT693B") -> bool:
    """Parse the ``cm?`` reply: True when the MDT693A compatibility mode is on.

    Accepts the words (``[MDT693A Compatibility Mode On]``) or the digit the help text names
    (``1``, ``[0]``).

    Raises
    ------
    ProtocolError
        Neither.
    """
    words = _ON_OFF.findall(body) if isinstance(body, str) else []
    digit = _DIGIT.match(body) if isinstance(body, str) else None
    if len(words) == 1:
        return words[0].lower() == "on"
    if digit is not None:
        return digit.group(1) == "1"
    raise ProtocolError(device, f"expected the cm? reply '[MDT693A Compatibility Mode On]' or 'Off' (or 1, 0), "
                        f"got {body[:60]!r}")


def command_set_after_probe(probe: Reply, compatibility: Reply | None) -> CommandSetName | None:
    """Which command set a unit speaks, from its answers to ``echo=0`` and (if asked) ``cm?``.

    Parameters
    ----------
    probe
        The answer to ``echo=0``: prompt ``>`` only the B command set uses; ``!`` means the unit does
        not know the command (an MDT693A, or a B unit in compatibility mode); ``*`` is either (the B
        firmware 1.05 prompt), so ``cm?`` decides.
    compatibility
        The answer to ``cm?``, or None when it has not been asked yet.

    Returns
    -------
    ``"mdt693b"``, ``"mdt693a"``, or None when ``cm?`` must be asked first.

    Raises
    ------
    ProtocolError
        The ``cm?`` reply is not one :func:`parse_compatibility_mode` accepts.
    """
    if probe.prompt == ">":
        return "mdt693b"
    if probe.prompt == "!":
        return "mdt693a"
    if compatibility is None:
        return None
    if compatibility.error is not None:  # a B firmware without the compatibility mode
        return "mdt693b"
    return "mdt693a" if parse_compatibility_mode(compatibility.body) else "mdt693b"
