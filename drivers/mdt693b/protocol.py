"""Thorlabs MDT693B / MDT694B piezo controller: the ASCII protocol as pure encode/parse (no I/O).

The controllers speak 115200 8N1 over a USB virtual COM port. The host sends a command terminated
by a carriage return; the controller answers with an optional echo of the command, an optional reply
body and a prompt character::

    host    b"xvoltage?\\r"
    device  b"xvoltage?\\r[  12.34]\\r>"      echo on  (the echo ends with CR)
    device  b"[  12.34]\\r>"                 echo off
    host    b"xvoltage=12.34\\r"
    device  b">"                            a set command has no reply body

Where firmware versions differ this module accepts all the variants we found documented:

* Prompt: ``>`` (firmware 1.10 of the MDT693B/694B) or ``*`` (firmware 1.05 and the MDT693A
  compatibility mode). Logs of the ``*`` firmware show the prompt character *before* a query's
  reply as well as after it (``b"vlimit?\\r*[ 100]\\r*"``), so when a body is expected, leading prompt
  characters are skipped (:func:`split_reply` with ``expect_body=True``).
* Numbers: bracketed (``[ 100]``, ``[  24.8]``, ``[  0.24]``) or bare (``0``, ``150.5``, as
  ``xmin?``/``xmax?`` answer on firmware 1.05; that is C's ``%g``, so ``1e-05`` is read too).
* ``vlimit?``: the switch voltage (``[ 100]``) or, as the built-in help text words it, the switch
  position (0 = 75 V, 1 = 100 V, 2 = 150 V).
* Errors: firmware 1.10 answers an unknown command with ``CMD_NOT_DEFINED`` (and a bad argument with
  ``CMD_ARG_INVALID``) before the prompt; the MDT693A-compatible firmware answers ``!`` instead of a
  prompt. Both become a :class:`Reply` whose :attr:`Reply.error` names the problem.

Every parser raises only :class:`~wavestack.drivers.errors.ProtocolError` on bytes the protocol does
not allow (non-ASCII, a missing echo, an unparsable number, an over-long reply); the encoders raise
``ValueError`` for a bad argument, since no bytes exist yet.

References: Thorlabs MDT693B/MDT694B manual, section "Command list" (the ``?`` command prints the
same list on the device); public logs of firmware 1.05 and 1.10 sessions.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from wavestack.drivers._checks import is_finite_real
from wavestack.drivers.errors import ProtocolError

#: Command terminator the host sends.
TERMINATOR = b"\r"
#: Prompt characters that end a reply (``>`` firmware 1.10, ``*`` firmware 1.05 / compatibility).
PROMPTS = b">*"
#: What the MDT693A-compatible firmware sends instead of a prompt after a command it does not know.
ERROR_MARK = b"!"
#: Reply bodies that mean the controller rejected the command.
ERROR_REPLIES = ("CMD_NOT_DEFINED", "CMD_ARG_INVALID", "!")
#: Output axes of the MDT693B (the MDT694B has only ``x``).
AXES = ("x", "y", "z")
#: Settings of the front-panel output-voltage limit switch, volts.
VLIMIT_SETTINGS_V = (75.0, 100.0, 150.0)
#: A reply longer than this without a prompt is garbage, not a slow device.
MAX_REPLY_BYTES = 4096

_DEFAULT_DEVICE = "MDT693B"
_COMMAND = re.compile(r"^[A-Za-z?%][A-Za-z0-9?=.,+\- ]*$")
_NUMBER = re.compile(r"^\s*(?:\[\s*(?P<bracketed>[^\[\]]*?)\s*\]|(?P<bare>[^\[\]]*?))\s*$")
_FLOAT = re.compile(r"^[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?$", re.ASCII)  # a C "%g" may use an exponent
_LINE_BREAKS = b"\r\n"


@dataclass(frozen=True)
class Reply:
    """One complete answer of the controller, echo removed.

    Attributes
    ----------
    body
        The reply text between echo and prompt, CR/LF and blanks stripped at both ends; lines inside
        (``id?``) stay separated by ``"\\r"``. Empty for a set command.
    prompt
        The character that ended the reply: ``">"``, ``"*"`` or ``"!"`` (compatibility-mode error).
    """

    body: str
    prompt: str

    @property
    def error(self) -> str | None:
        """The controller's error text (``CMD_NOT_DEFINED``, ``CMD_ARG_INVALID``, ``!``) or None."""
        if self.prompt == "!":
            return "!"
        first = self.body.split("\r", 1)[0].strip()
        return first if first in ERROR_REPLIES else None


@dataclass(frozen=True)
class DeviceIdentity:
    """What ``id?`` reports.

    Attributes
    ----------
    model
        ``"MDT693B"``, ``"MDT694B"`` (the word after ``Model``).
    firmware
        Firmware version string, ``""`` when the reply has no ``Firmware Version`` line.
    voltage_range
        E.g. ``"0V to 150V"``, ``""`` when absent.
    serial_number, friendly_name
        ``""`` when absent (firmware 1.05 has neither line).
    raw
        The whole reply body.
    """

    model: str
    firmware: str
    voltage_range: str
    serial_number: str
    friendly_name: str
    raw: str

    @property
    def axes(self) -> tuple[str, ...]:
        """Output axes of this model: ``("x",)`` for an MDT694, else ``("x", "y", "z")``."""
        return ("x",) if self.model.upper().startswith("MDT694") else AXES


def encode_command(command: str) -> bytes:
    """Encode one command line.

    Parameters
    ----------
    command
        Printable ASCII without terminator or prompt characters, e.g. ``"vlimit?"``.

    Returns
    -------
    bytes
        The command followed by :data:`TERMINATOR`.

    Raises
    ------
    ValueError
        Empty, non-ASCII, or containing characters the protocol reserves (CR, LF, ``>``, ``*``, ``!``);
        ``%`` only as the first character (the MDT693A's limit switch query).
    """
    if not isinstance(command, str) or not _COMMAND.fullmatch(command):  # match's "$" lets a final LF through
        raise ValueError(f"not an MDT693B command: {command!r} (expected printable ASCII such as 'xvoltage?')")
    return command.encode("ascii") + TERMINATOR


def encode_set_voltage(axis: str, volts: float) -> bytes:
    """Encode ``<axis>voltage=<volts>`` with two decimals (the DAC resolution is coarser).

    Parameters
    ----------
    axis
        ``"x"``, ``"y"`` or ``"z"``.
    volts
        Output voltage, V; finite and >= 0.

    Raises
    ------
    ValueError
        Unknown axis or a non-finite or negative voltage.

    Examples
    --------
    >>> encode_set_voltage("x", 12.345)
    b'xvoltage=12.35\\r'
    """
    _check_axis(axis)
    if not is_finite_real(volts) or volts < 0:
        raise ValueError(f"voltage must be a finite number >= 0 V, got {volts!r}")
    return encode_command(f"{axis}voltage={float(volts):.2f}")


def encode_query(axis: str, quantity: str) -> bytes:
    """Encode a per-axis query: ``quantity`` is ``"voltage"``, ``"min"`` or ``"max"``.

    Raises
    ------
    ValueError
        Unknown axis or quantity.
    """
    _check_axis(axis)
    if quantity not in ("voltage", "min", "max"):
        raise ValueError(f"quantity must be 'voltage', 'min' or 'max', got {quantity!r}")
    return encode_command(f"{axis}{quantity}?")


def split_reply(
    buffer: bytes,
    *,
    echo_of: bytes | None,
    expect_body: bool,
    prompts: bytes = PROMPTS,
    device: str = _DEFAULT_DEVICE,
    echo_optional: bool = False,
) -> tuple[Reply | None, bytes]:
    """Cut the first complete reply off a received byte stream.

    Parameters
    ----------
    buffer
        Bytes received so far for this command.
    echo_of
        The command as sent, without terminator, when the controller echoes; None when echo is off.
    expect_body
        True for a query: prompt characters and line breaks before the body are skipped (the ``*``
        firmware prints its prompt before the reply too).
    prompts
        Characters accepted as the prompt (the detected one, or :data:`PROMPTS` while detecting).
    device
        Name used in error messages.
    echo_optional
        True: the echo of ``echo_of`` (followed by CR) may come first or not at all, and is compared
        without regard to case (the MDT693A echoes in lower case). Used in the MDT693A command set,
        where the driver does not switch the echo off.

    Returns
    -------
    (Reply or None, bytes)
        The reply and the bytes after its prompt, or ``(None, buffer)`` when more bytes are needed.

    Raises
    ------
    ProtocolError
        The echo differs from the command, the body holds non-ASCII or control bytes, or
        :data:`MAX_REPLY_BYTES` arrived without a prompt.
    """
    position = 0
    if echo_of is not None:
        expected = echo_of + TERMINATOR if echo_optional else echo_of
        head = buffer[: len(expected)]
        if (expected.lower() if echo_optional else expected).startswith(head.lower() if echo_optional else head):
            if len(head) < len(expected):
                return None, buffer
            position = len(expected)
        elif not echo_optional:
            raise ProtocolError(device, f"expected the echo {echo_of!r}, got {bytes(head)!r}")
    skip = _LINE_BREAKS + b" " + (prompts if expect_body else b"")
    while position < len(buffer) and buffer[position] in skip:
        position += 1
    ends = prompts + ERROR_MARK
    for index in range(position, len(buffer)):
        if buffer[index] in ends:
            body = _decode_body(buffer[position:index], device)
            return Reply(body, chr(buffer[index])), buffer[index + 1:]
    if len(buffer) > MAX_REPLY_BYTES:
        raise ProtocolError(device, f"no prompt after {len(buffer)} bytes (expected one of {ends!r})")
    return None, buffer


def parse_number(body: str, *, device: str = _DEFAULT_DEVICE) -> float:
    """Parse a numeric reply, bracketed (``[  12.34]``) or bare (``150.5``, ``1e-05``).

    Returns
    -------
    float
        The value (finite).

    Raises
    ------
    ProtocolError
        Not exactly one decimal number.
    """
    match = _NUMBER.match(body) if isinstance(body, str) else None
    text = None if match is None else (match.group("bracketed") if match.group("bracketed") is not None
                                       else match.group("bare"))
    value = float(text) if text is not None and _FLOAT.fullmatch(text) else math.nan
    if not math.isfinite(value):  # also catches a digit string too long for a double
        raise ProtocolError(device, f"expected a number such as '[ 12.34]', got {body[:40]!r}")
    return value


def parse_vlimit(body: str, *, device: str = _DEFAULT_DEVICE) -> float:
    """Parse the ``vlimit?`` reply into the limit switch voltage, V (75, 100 or 150).

    Accepts the voltage itself (``[ 100]``) or the switch position 0, 1, 2.

    Raises
    ------
    ProtocolError
        Any other value.
    """
    value = parse_number(body, device=device)
    if value in VLIMIT_SETTINGS_V:
        return value
    if value in (0.0, 1.0, 2.0):
        return VLIMIT_SETTINGS_V[int(value)]
    raise ProtocolError(device, f"expected the limit switch at 75, 100 or 150 V (or 0, 1, 2), got {body!r}")


def parse_id(body: str, *, device: str = _DEFAULT_DEVICE) -> DeviceIdentity:
    """Parse the multi-line ``id?`` reply.

    Expected lines (absent ones are left empty, except the model)::

        Model MDT693B Piezo Control Module
        Firmware Version: 1.10
        Voltage Range: 0V to 150V
        Serial#:150226175403
        Friendly Name:MDT693B

    Raises
    ------
    ProtocolError
        No ``Model ...`` line.
    """
    if not isinstance(body, str):
        raise ProtocolError(device, f"expected the id? text, got {body!r}")
    lines = [line.strip() for line in re.split(r"[\r\n]+", body) if line.strip()]
    fields: dict[str, str] = {}
    model = ""
    for line in lines:
        if line.startswith("Model ") and not model:
            words = line.split()
            model = words[1] if len(words) > 1 else ""
        elif ":" in line:
            key, _, value = line.partition(":")
            fields.setdefault(key.strip().lower(), value.strip())
    if not model:
        raise ProtocolError(device, f"expected an id? reply with a 'Model MDT69x...' line, got {body[:80]!r}")
    return DeviceIdentity(
        model=model,
        firmware=fields.get("firmware version", ""),
        voltage_range=fields.get("voltage range", ""),
        serial_number=fields.get("serial#", ""),
        friendly_name=fields.get("friendly name", ""),
        raw=body,
    )


def _check_axis(axis: str) -> None:
    if axis not in AXES:
        raise ValueError(f"axis must be one of {AXES}, got {axis!r}")


def _decode_body(raw: bytes, device: str) -> str:
    for byte in raw:
        if not (32 <= byte < 127 or byte in b"\r\n\t"):
            raise ProtocolError(device, f"expected printable ASCII in the reply, got {bytes(raw[:40])!r}")
    return raw.decode("ascii").strip(" \r\n\t")
