"""The MDT693A command set, as the controller answers it: an MDT693A, or a B unit in compatibility mode.

Written from the controller's documentation, not from the driver: the MDT693B firmware 1.10 help text
(the list its ``?`` command prints, the Thorlabs MDT693B/MDT694B manual's command list) names
``CM?``/``CM=`` "MDT693A compatibility mode (0=Off, 1=On)" (the MDT694B says MDT694A); a public
firmware 1.05 log shows the ``cm?`` reply as words, ``[MDT693A Compatibility Mode Off]``. The
single-letter set is the MDT693A manual's (computer interface section; read through the host programs
written against it and logs of a real MDT693A, firmware 3.01, since the manual itself was not
reachable): ``I`` identity, ``XR?`` read an output, ``XV<volts>`` set it, ``XL?``/``XH?`` and
``XL<volts>``/``XH<volts>`` the lower and upper output limit (likewise ``Y``, ``Z``), ``AV<volts>``
all outputs (three-axis models), ``%`` the limit switch, ``E`` echo.

Behaviour modelled, with the readings taken where the sources leave room:

* Prompt ``*``; a query answers ``*<body>\\r*`` (the prompt before the reply too, as the ``*``
  firmware logs show); a set command answers ``*``.
* Anything the set does not hold, the B unit's long commands included (whether real firmware in this
  mode still takes them is not documented; refusing them is the stricter test of a host), and a
  malformed or out-of-range argument answer ``!`` instead of the prompt.
* The echo repeats the command in lower case, as the real MDT693A does; ``E`` toggles it (the sources
  show ``E`` alone; what a digit after it means is not documented, so ``E0``/``E1`` are refused).
* Voltages and limits answer bracketed with one decimal (``[  12.3]``), the limit switch as
  ``[ 150]``; a setpoint beyond the limits or the switch is clipped silently, as in the B set.
* ``cm=0`` on a B unit returns to its own set; the answer already ends with that set's prompt. A real
  MDT693A has no ``cm`` command.
"""

from __future__ import annotations

import re

from wavestack.simulators.mdt693b.personality import AxisState, MDT693BPersonality

__all__ = ["REFUSED", "MDT693ACommands", "frame_mdt693a"]

#: What :meth:`MDT693ACommands._execute_mdt693a` returns for a command the set refuses.
REFUSED = "!"

_VOLTS = r"([+-]?(?:\d+(?:\.\d*)?|\.\d+))"
_AXIS_QUERY = re.compile(r"([xyz])([rlh])\?")
_AXIS_SET = re.compile(r"([xyza])([vlh])" + _VOLTS)


def frame_mdt693a(outcome: str | None, prompt: bytes) -> bytes:
    """The bytes after the echo: ``*`` for a set, ``*<body>\\r*`` for a query, ``!`` when refused."""
    if outcome is None:
        return prompt
    if outcome == REFUSED:
        return REFUSED.encode("ascii")
    return b"*" + outcome.encode("ascii") + b"\r" + prompt


class MDT693ACommands:
    """The MDT693A command set of :class:`~wavestack.simulators.mdt693b.device.MDT693BDevice` (a mixin).

    The device owns the state this reads and changes; the attributes below name it.
    """

    personality: MDT693BPersonality
    vlimit_v: float
    _echo: bool
    _compatibility: bool
    _axes: dict[str, AxisState]

    def _set_output(self, axis: str, volts: float, changes: list[tuple[str, float]]) -> None:
        raise NotImplementedError  # the device's, shared by both command sets

    def _execute_mdt693a(self, command: str, changes: list[tuple[str, float]]) -> str | None:
        """Run one MDT693A command (lower case, stripped; lock held): the reply body, None or REFUSED."""
        if command == "i":
            return self.personality.id_text()
        if command == "%":
            return f"[{int(self.vlimit_v):4d}]"
        if command == "e":
            self._echo = not self._echo
            return None
        if command.startswith("cm"):
            return self._compatibility_command(command)
        query = _AXIS_QUERY.fullmatch(command)
        if query and query.group(1) in self._axes:
            state = self._axes[query.group(1)]
            value = {"r": state.volts, "l": state.min_v, "h": state.max_v}[query.group(2)]
            return f"[{value:6.1f}]"
        setting = _AXIS_SET.fullmatch(command)
        if setting is None or not 0.0 <= float(setting.group(3)) <= 150.0:
            return REFUSED
        axis, quantity, volts = setting.group(1), setting.group(2), float(setting.group(3))
        if axis == "a" and quantity == "v" and len(self._axes) == 3:
            for name in self._axes:
                self._set_output(name, volts, changes)
            return None
        if axis not in self._axes:
            return REFUSED
        if quantity == "v":
            self._set_output(axis, volts, changes)
        else:
            self._axes[axis].set_limit("min" if quantity == "l" else "max", volts)
        return None

    def _compatibility_command(self, command: str) -> str | None:
        if self.personality.model == "MDT693A":  # the older controller has no such switch
            return REFUSED
        if command == "cm?":
            return f"[{self.personality.compatibility_model} Compatibility Mode On]"
        if command == "cm=0":
            self._compatibility = False
            return None
        return None if command == "cm=1" else REFUSED
