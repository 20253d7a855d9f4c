"""The MDT693B / MDT694B piezo controller seen from the other end of the wire.

Written from the controller's command description (the list its ``?`` command prints and the
Thorlabs manual), not from the driver's parser, so a misreading in one is not copied into the other.
Bytes in, bytes out: :meth:`MDT693BDevice.feed` takes what the host wrote and returns the bytes the
controller sends back; a transport (the ``sim://`` serial handler or :class:`PtyBridge`) carries
them and honours :meth:`MDT693BDevice.delivery_plan` for replies that arrive in pieces.

Behaviour modelled (firmware 1.10 unless noted):

* A command ends with CR; LF is ignored; commands are case-insensitive. A bare CR answers with the
  prompt alone (an assumption; not documented).
* A line longer than 256 bytes is refused (``CMD_NOT_DEFINED``, ``!`` in the MDT693A set), not run
  cut short (an assumption: the firmware's buffer size is not documented).
* Echo on (the power-on default): the command line and a CR come back before the reply.
* A query answers ``<body>\\r<prompt>``; a set command answers the prompt alone. With the ``*``
  prompt (firmware 1.05) a query's body is preceded by a ``*`` too, as logs of that firmware show.
* Voltages answer bracketed with a fixed width (``[  12.34]``); ``vlimit?`` answers ``[ 150]``;
  ``xmin?``/``xmax?`` answer a bare number (``150``), as firmware 1.05 does.
* ``xvoltage=V`` beyond the axis limits or the front-panel switch is clipped silently: the output
  cannot exceed the hardware limit, so only a read-back reveals it.
* An unknown command answers ``CMD_NOT_DEFINED``, a malformed argument ``CMD_ARG_INVALID``, each
  followed directly by the prompt (firmware 1.10 sends ``CMD_NOT_DEFINED>``; the ``*`` personality
  uses the same text, for want of a record of that firmware).
* ``cm?`` answers ``[MDT693A Compatibility Mode Off]`` (``MDT694A`` on the one-axis model); ``cm=1``
  switches to the MDT693A command set (:mod:`~wavestack.simulators.mdt693b.compatibility`), whose
  prompt ends that very answer. The ``MDT693A`` model speaks only that set.
"""

from __future__ import annotations

import logging
import random
import re
import threading
from collections import deque
from collections.abc import Callable

from wavestack.simulators.mdt693b.compatibility import REFUSED, MDT693ACommands, frame_mdt693a
from wavestack.simulators.mdt693b.personality import AxisState, MDT693BFaults, MDT693BPersonality

logger = logging.getLogger(__name__)

VoltageListener = Callable[[str, float], None]

_ERRORS = ("CMD_NOT_DEFINED", "CMD_ARG_INVALID")
_MAX_LINE = 256
_SPLIT_DELAY_S = 0.01  # gap between the pieces of a split reply; well below any driver timeout
#: Command lines kept in :attr:`MDT693BDevice.commands` (the newest; a long run's memory stays flat).
COMMAND_HISTORY = 10_000
#: Bytes kept in :attr:`MDT693BDevice.received` (the newest).
RECEIVED_HISTORY = 256 * 1024


class MDT693BDevice(MDT693ACommands):
    """State machine of one simulated MDT693B / MDT694B.

    Parameters
    ----------
    personality
        Model, firmware, prompt, echo default, limit switch.
    on_voltage_change
        Called as ``on_voltage_change(axis, volts)`` after an output changes (outside the lock), so
        a simulated camera can render the phase the piezo produces. May be set later as attribute.
    seed
        Seed of the garbage generator.

    Attributes
    ----------
    faults
        :class:`MDT693BFaults` of this instance.
    vlimit_v
        Position of the front-panel limit switch, V; a test may turn it (75, 100, 150).
    """

    def __init__(self, personality: MDT693BPersonality | None = None, *,
                 on_voltage_change: VoltageListener | None = None, seed: int = 0) -> None:
        self.personality = personality or MDT693BPersonality()
        self.faults = MDT693BFaults()
        self.on_voltage_change = on_voltage_change
        self.vlimit_v = self.personality.vlimit_v
        self._echo = self.personality.echo
        self._compatibility = self.personality.compatibility_mode or self.personality.model == "MDT693A"
        self._axes = {name: AxisState() for name in self.personality.axes}
        self._line = bytearray()
        self._line_too_long = False  # bytes of the present line were dropped beyond _MAX_LINE
        self._received = bytearray()
        self._commands: deque[str] = deque(maxlen=COMMAND_HISTORY)
        self.commands_received = 0  # every command line ever, also those the history forgot
        self._random = random.Random(seed)
        self._lock = threading.Lock()

    # ----------------------------------------------------------------- ground truth for tests
    def voltage(self, axis: str) -> float:
        """Present output voltage of ``axis``, V."""
        with self._lock:
            return self._axis(axis).volts

    def set_axis_limits(self, axis: str, min_v: float, max_v: float) -> None:
        """Set the per-axis output limits (what ``xmin=``/``xmax=`` would), V."""
        if not 0.0 <= min_v <= max_v <= 150.0:
            raise ValueError(f"expected 0 <= min_v <= max_v <= 150 V, got {min_v!r}, {max_v!r}")
        with self._lock:
            state = self._axis(axis)
            state.min_v, state.max_v = float(min_v), float(max_v)

    @property
    def compatibility_mode(self) -> bool:
        """True while the controller speaks the MDT693A command set."""
        with self._lock:
            return self._compatibility

    @property
    def echo(self) -> bool:
        """Present echo setting."""
        with self._lock:
            return self._echo

    @property
    def received(self) -> bytes:
        """The newest bytes the host has written, in order (also while silent or garbled).

        At most :data:`RECEIVED_HISTORY` bytes: a long run's memory stays flat.
        """
        with self._lock:
            return bytes(self._received[-RECEIVED_HISTORY:])

    @property
    def commands(self) -> tuple[str, ...]:
        """The newest :data:`COMMAND_HISTORY` command lines received (terminator removed), in order."""
        with self._lock:
            return tuple(self._commands)

    # ------------------------------------------------------------------------------ the wire
    def feed(self, data: bytes) -> bytes:
        """Take bytes the host wrote; return the bytes the controller answers (maybe empty).

        Partial lines are kept until their CR arrives. Unplugged, nothing is read or answered.
        """
        if self.faults.unplugged:
            return b""
        out = bytearray()
        changes: list[tuple[str, float]] = []
        with self._lock:
            self._received += data
            if len(self._received) > 2 * RECEIVED_HISTORY:  # trimmed now and then: amortised O(1) per byte
                del self._received[:-RECEIVED_HISTORY]
            for byte in data:
                if byte == 0x0A:
                    continue
                if byte != 0x0D:
                    if len(self._line) < _MAX_LINE:
                        self._line.append(byte)
                    else:
                        self._line_too_long = True
                    continue
                line, self._line = bytes(self._line), bytearray()
                too_long, self._line_too_long = self._line_too_long, False
                out += self._answer(line, changes, too_long=too_long)
        for axis, volts in changes:
            if self.on_voltage_change is not None:
                self.on_voltage_change(axis, volts)
        return bytes(out)

    def delivery_plan(self, reply: bytes) -> tuple[tuple[float, bytes], ...]:
        """How a reply reaches the host: ``(delay_s, chunk)`` pairs, delay counted from the previous chunk."""
        if not reply:
            return ()
        if not self.faults.split_replies or len(reply) < 3:
            return ((0.0, reply),)
        cut1, cut2 = len(reply) // 3, 2 * len(reply) // 3
        return ((0.0, reply[:cut1]), (_SPLIT_DELAY_S, reply[cut1:cut2]), (_SPLIT_DELAY_S, reply[cut2:]))

    # ------------------------------------------------------------------------------ internals
    def _axis(self, axis: str) -> AxisState:
        try:
            return self._axes[axis]
        except KeyError:
            raise ValueError(f"{self.personality.model} has axes {tuple(self._axes)}, not {axis!r}") from None

    def _answer(self, line: bytes, changes: list[tuple[str, float]], *, too_long: bool = False) -> bytes:
        """The bytes answering one line; a line cut at ``_MAX_LINE`` is refused, never run truncated."""
        text = line.decode("latin-1")
        self._commands.append(text)
        self.commands_received += 1
        if self.faults.silent:
            return b""
        if self._compatibility:
            echo = line.lower() + b"\r" if self._echo else b""  # the MDT693A echoes in lower case
            outcome = REFUSED if too_long else self._execute_mdt693a(text.strip().lower(), changes)
            prompt = b"*" if self._compatibility else self.personality.prompt.encode()  # cm=0 switched it
            if self.faults.garbage:
                return echo + self._noise() + prompt
            return echo + frame_mdt693a(outcome, prompt)
        echo = line + b"\r" if self._echo else b""
        body = "CMD_NOT_DEFINED" if too_long else self._execute(text.strip().lower(), changes)
        prompt = b"*" if self._compatibility else self.personality.prompt.encode()  # cm=1 switched it
        if self.faults.garbage:
            return echo + self._noise() + prompt
        if body is None:
            return echo + prompt
        if body in _ERRORS:  # firmware 1.10 sends b"CMD_NOT_DEFINED>" without a line break
            return echo + body.encode("ascii") + prompt
        lead = prompt if self.personality.prompt == "*" else b""
        return echo + lead + body.encode("ascii") + b"\r" + prompt

    def _execute(self, command: str, changes: list[tuple[str, float]]) -> str | None:
        """Run one command; the reply body, or None for a command without one."""
        if command == "":
            return None
        if command == "id?":
            return self.personality.id_text()
        if command == "vlimit?":
            return f"[{int(self.vlimit_v):4d}]"
        if command == "echo?":
            return "[Echo On]" if self._echo else "[Echo Off]"
        if command == "serial?":
            return self.personality.serial_number
        if command == "friendly?":
            return self.personality.friendly_name
        if command == "cm?":
            return f"[{self.personality.compatibility_model} Compatibility Mode Off]"
        if command.startswith("cm="):
            if command[3:].strip() not in ("0", "1"):
                return "CMD_ARG_INVALID"
            self._compatibility = command[3:].strip() == "1"
            return None
        if command.startswith("echo="):
            value = command[5:].strip()
            if value not in ("0", "1"):
                return "CMD_ARG_INVALID"
            self._echo = value == "1"
            return None
        match = re.fullmatch(r"([xyz])(voltage|min|max)([?=])(.*)", command)
        if match and match.group(1) in self._axes:
            return self._axis_command(*match.groups(), changes)
        if command.startswith("allvoltage=") and self.personality.model == "MDT693B":
            volts = _number(command[len("allvoltage="):])
            if volts is None:
                return "CMD_ARG_INVALID"
            for name in self._axes:
                self._set_output(name, volts, changes)
            return None
        if command == "xyzvoltage?" and self.personality.model == "MDT693B":
            return "[" + ",".join(self._format_volts(self._axes[a].volts) for a in "xyz") + "]"
        return "CMD_NOT_DEFINED"

    def _axis_command(self, axis: str, quantity: str, verb: str, argument: str,
                      changes: list[tuple[str, float]]) -> str | None:
        state = self._axes[axis]
        if verb == "?":
            if argument.strip():
                return "CMD_NOT_DEFINED"
            if quantity == "voltage":
                return f"[{self._format_volts(state.volts)}]"
            return f"{state.min_v if quantity == 'min' else state.max_v:g}"
        volts = _number(argument)
        if volts is None or not 0.0 <= volts <= 150.0:
            return "CMD_ARG_INVALID"
        if quantity == "voltage":
            self._set_output(axis, volts, changes)
        else:
            state.set_limit("min" if quantity == "min" else "max", volts)
        return None

    def _set_output(self, axis: str, volts: float, changes: list[tuple[str, float]]) -> None:
        state = self._axes[axis]
        high = min(state.max_v, self.vlimit_v)
        clipped = min(max(volts, state.min_v), high)
        # the output DAC resolves finer than the display; the reply rounds to `decimals`
        output = round(clipped, 3)
        if output != state.volts:
            state.volts = output
            changes.append((axis, output))
            logger.debug("simulated %s: %s axis -> %.3f V", self.personality.model, axis, output)

    def _noise(self) -> bytes:
        return bytes(self._random.randrange(0x80, 0x100) for _ in range(self._random.randrange(4, 16)))

    def _format_volts(self, volts: float) -> str:
        return f"{volts:6.{self.personality.decimals}f}"


def _number(text: str) -> float | None:
    text = text.strip()
    if not re.fullmatch(r"[+-]?(\d+(\.\d*)?|\.\d+)", text):
        return None
    return float(text)
