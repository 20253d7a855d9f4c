"""Driver for the Thorlabs MDT693B (3-axis) / MDT694B (1-axis) open-loop piezo controller.

The driver *has* a :class:`~wavestack.drivers.link.ByteLink` (115200 8N1), so the same code runs on
``/dev/ttyUSB0``, ``COM3``, a pseudo-terminal path, ``socket://host:port``, ``rfc2217://``,
``tcp://host:port`` and ``sim://mdt693b``. Bytes are encoded and framed by
:mod:`wavestack.drivers.mdt693b.protocol` (a reply ends at the prompt), the voltage limits are
combined by :mod:`wavestack.drivers.mdt693b.limits`; this module knows what to ask, enforces the
limits and handles the errors.

On :meth:`MDT693B.open` the driver sends ``echo=0`` (the echo doubles the traffic and would need a
second parse path; whichever prompt, ``>`` or ``*``, ends that reply is the device's prompt from then
on), then reads ``id?``, ``vlimit?`` and ``<axis>min?``/``<axis>max?`` for every configured axis.
After a :class:`ProtocolError` or :class:`DeviceTimeout` the next command first resynchronises:
it flushes the input, sends ``echo=0`` again, waits for the prompt and for the line to fall quiet.
That also recovers a controller that was power-cycled (echo back on) behind the driver's back.

MDT693A command set. A B unit whose MDT693A compatibility mode is on (``cm=1``, kept by the
controller and left on by other host software), and a real MDT693A, speak the older single-letter
commands (:mod:`~wavestack.drivers.mdt693b.command_sets`). With ``command_set="auto"`` (the
default) the driver finds out at open, since only the controller knows its mode: a unit that
answers ``echo=0`` with ``>`` speaks the B set, one that answers ``!`` (unknown command) the A set,
and after ``*`` (the prompt of B firmware 1.05 and of the A set) ``cm?`` decides. ``"mdt693a"``
never sends a B command (for a real MDT693A, whose reaction to one is not documented);
``"mdt693b"`` refuses a unit in compatibility mode. In the A set the echo is not switched off but
accepted, and the resynchronisation sends the harmless ``%`` instead of ``echo=0``.
:meth:`MDT693B.set_compatibility_mode` switches a B unit and reads everything again.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial

from wavestack.drivers._checks import is_finite_real
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.link import ByteLink, LinkedDevice
from wavestack.drivers.mdt693b.command_sets import (
    A_COMMANDS,
    B_COMMANDS,
    COMMAND_SETS,
    CommandSet,
    command_set_after_probe,
    encode_compatibility_mode,
)
from wavestack.drivers.mdt693b.limits import AxisLimits, _effective_limits, _on_wire
from wavestack.drivers.mdt693b.protocol import (
    AXES,
    PROMPTS,
    DeviceIdentity,
    Reply,
    encode_command,
    parse_id,
    parse_number,
    parse_vlimit,
    split_reply,
)

__all__ = ["MDT693B", "AxisLimits", "VoltageReading"]

logger = logging.getLogger(__name__)

_HARDWARE_MAX_V = 150.0
_MODE_HINT = (" (an MDT693A answer: the controller speaks the MDT693A command set, its compatibility mode is "
              "on; construct the driver with command_set='auto' or 'mdt693a', or switch the mode off)")


@dataclass(frozen=True)
class VoltageReading:
    """Result of one :meth:`MDT693B.set_voltage`.

    Attributes
    ----------
    axis
        ``"x"``, ``"y"`` or ``"z"``.
    requested_v
        The voltage asked for, V.
    commanded_v
        The voltage sent, V: ``requested_v`` (or its clamped value) rounded to the two decimals on
        the wire.
    readback_v
        What ``<axis>voltage?`` reported afterwards, V.
    clamped
        True when ``requested_v`` lay outside the limits and was clamped to them.
    """

    axis: str
    requested_v: float
    commanded_v: float
    readback_v: float
    clamped: bool


class MDT693B(LinkedDevice):
    """Thorlabs MDT693B / MDT694B piezo controller on a serial URL.

    Parameters
    ----------
    url
        Anything ``serial.serial_for_url`` opens: ``/dev/ttyUSB0``, ``COM3``, ``/dev/pts/5``,
        ``socket://host:port``, ``sim://mdt693b`` (after ``register_serial_simulators()``).
    axes
        Axes this station drives, subset of ``("x", "y", "z")``; an MDT694B has only ``x``.
    software_min_v, software_max_v
        Software limits, V, within 0..150; the effective limits also honour the device's.
    readback_tolerance_v
        Largest accepted |read-back - command|, V (the controller resolves ~0.1-0.2 V).
    timeout_s
        Per-exchange timeout used by :meth:`open`, s.
    command_set
        ``"auto"`` (detect at open), ``"mdt693b"`` or ``"mdt693a"`` (the MDT693A command set of an
        MDT693A or of a B unit in compatibility mode); see the module docstring.

    Notes
    -----
    Thread-safe: one lock serialises every command exchange (a set and its read-back together).
    :meth:`close` leaves the outputs where they are, as a piezo holding position should.
    """

    def __init__(
        self,
        url: str,
        *,
        axes: Sequence[str] = ("x",),
        software_min_v: float = 0.0,
        software_max_v: float = _HARDWARE_MAX_V,
        readback_tolerance_v: float = 0.5,
        timeout_s: float = 1.0,
        command_set: str = "auto",
    ) -> None:
        axes = tuple(axes)
        if not axes or len(set(axes)) != len(axes) or not set(axes) <= set(AXES):
            raise ValueError(f"axes must be distinct members of {AXES}, got {axes!r}")
        if not 0.0 <= software_min_v < software_max_v <= _HARDWARE_MAX_V:
            raise ValueError(f"expected 0 <= software_min_v < software_max_v <= 150 V, "
                             f"got {software_min_v!r}, {software_max_v!r}")
        if command_set != "auto" and command_set not in COMMAND_SETS:
            raise ValueError(f"command_set must be 'auto', 'mdt693b' or 'mdt693a', got {command_set!r}")
        if not readback_tolerance_v > 0 or not timeout_s > 0:
            raise ValueError(f"readback_tolerance_v and timeout_s must be > 0, "
                             f"got {readback_tolerance_v!r}, {timeout_s!r}")
        self.url = url
        self.axes = axes
        self.software_min_v = float(software_min_v)
        self.software_max_v = float(software_max_v)
        self.readback_tolerance_v = float(readback_tolerance_v)
        self.timeout_s = float(timeout_s)
        self.configured_command_set = command_set
        self._lock = threading.RLock()
        self._link = ByteLink(url, lambda: self.name)
        self._commands: CommandSet = B_COMMANDS  # in the A set an echo is accepted and the resync sends %
        self._prompt = PROMPTS
        self._needs_resync = False  # after a garbled or missing reply: the next exchange resynchronises first
        self._identity: DeviceIdentity | None = None
        self._vlimit_v = _HARDWARE_MAX_V
        self._limits: dict[str, AxisLimits] = {}

    # ------------------------------------------------------------------------------ lifecycle
    @property
    def name(self) -> str:
        """Who this is in messages: ``"MDT693B on /dev/ttyUSB0"``."""
        model = self._identity.model if self._identity is not None else "MDT693B"
        return f"{model} on {self.url}"

    def _handshake(self, timeout_s: float) -> None:
        """Synchronise, settle the command set (detect it for ``"auto"``), read identity and limits.

        Called by :meth:`open` (from :class:`~wavestack.drivers.link.LinkedDevice`): open the port,
        switch echo off, detect the prompt and read identity and limits; ``timeout_s`` per exchange.
        """
        self._identity, self._needs_resync, self._prompt = None, False, PROMPTS
        self._settle_command_set(timeout_s, self.configured_command_set)
        logger.info("%s open: %s command set, firmware %s, limit switch %.0f V, limits %s", self.name,
                    self._commands.name, self._identity.firmware if self._identity else "?", self._vlimit_v,
                    {axis: (lim.min_v, lim.max_v) for axis, lim in self._limits.items()})

    # ------------------------------------------------------------------------------ queries
    @property
    def identity(self) -> DeviceIdentity:
        """What ``id?`` reported at open; raises :class:`DeviceDisconnected` before."""
        with self._lock:
            self._link.require_open()
            if self._identity is None:  # unreachable: open() fails without an identity
                raise DeviceDisconnected(self.name, "no identity; call open() again")
            return self._identity

    @property
    def command_set(self) -> str:
        """The command set in use: ``"mdt693b"`` or ``"mdt693a"`` (as detected or configured at open)."""
        with self._lock:
            self._link.require_open()
            return self._commands.name

    @property
    def vlimit_v(self) -> float:
        """Front-panel limit switch as read at open (or the last limit refresh), V."""
        with self._lock:
            self._link.require_open()
            return self._vlimit_v

    def limits(self, axis: str) -> AxisLimits:
        """Effective voltage limits of a configured axis (see :class:`AxisLimits`).

        Raises
        ------
        ValueError
            ``axis`` is not configured.
        DeviceDisconnected
            Not open.
        """
        self._check_axis(axis)
        with self._lock:
            self._link.require_open()
            return self._limits[axis]

    def read_voltage(self, axis: str, *, timeout_s: float) -> float:
        """Present output voltage of ``axis`` (``<axis>voltage?``), V.

        Raises
        ------
        ValueError
            ``axis`` not configured.
        DeviceTimeout, DeviceDisconnected, ProtocolError
            As for every exchange.
        """
        self._check_axis(axis)
        with self._lock:
            return self._query_number(self._commands.voltage_query(axis), time.monotonic() + timeout_s)

    # ----------------------------------------------------------------------------- commands
    def set_voltage(self, axis: str, volts: float, *, timeout_s: float, clamp: bool = False) -> VoltageReading:
        """Set the output of ``axis``, then read it back.

        Parameters
        ----------
        axis
            A configured axis.
        volts
            Requested output, V.
        timeout_s
            Budget for the set and the read-back together, s.
        clamp
            False: a setpoint outside :meth:`limits` raises :class:`LimitError` and nothing is sent.
            True: the setpoint is clamped to the limits and ``clamped=True`` is reported.

        Returns
        -------
        VoltageReading

        Raises
        ------
        ValueError
            Unknown axis or a non-finite ``volts`` (nothing sent).
        LimitError
            Out of limits and ``clamp`` is False (nothing sent).
        ProtocolError
            The controller rejected the command, answered garbage, or the read-back differs from the
            command by more than ``readback_tolerance_v`` (then the limits are read again, since a
            turned limit switch is the usual cause).
        DeviceTimeout, DeviceDisconnected
            As for every exchange.
        """
        self._check_axis(axis)
        if not is_finite_real(volts):
            raise ValueError(f"{self.name}: voltage must be a finite number, got {volts!r}")
        deadline = time.monotonic() + timeout_s
        with self._lock:
            self._link.require_open()
            limits = self._limits[axis]
            requested = float(volts)
            commanded = _on_wire(requested, limits)
            if not limits.contains(requested):
                if not clamp:
                    raise LimitError(self.name, f"{requested:g} V on axis {axis} is outside the limits "
                                     f"[{limits.min_v:g}, {limits.max_v:g}] V (software [{self.software_min_v:g}, "
                                     f"{self.software_max_v:g}], device [{limits.device_min_v:g}, "
                                     f"{limits.device_max_v:g}], limit switch {limits.vlimit_v:g} V); nothing sent")
                commanded = _on_wire(limits.clamp(requested), limits)
            self._command(self._commands.set_voltage(axis, commanded), expect_body=False, deadline=deadline, raw=True)
            readback = self._query_number(self._commands.voltage_query(axis), deadline)
            if abs(readback - commanded) > self.readback_tolerance_v:
                try:
                    self._refresh_limits(time.monotonic() + self.timeout_s)
                except DeviceError as error:
                    logger.warning("%s: could not read the limits again (%s)", self.name, error)
                raise ProtocolError(self.name, f"axis {axis} reads back {readback:g} V after {commanded:.2f} V was "
                                    f"commanded (tolerance {self.readback_tolerance_v:g} V); "
                                    f"limit switch now {self._vlimit_v:g} V")
            logger.debug("%s: %s -> %.2f V (read back %.2f V)", self.name, axis, commanded, readback)
            return VoltageReading(axis, requested, commanded, readback, not limits.contains(requested))

    def set_compatibility_mode(self, on: bool, *, timeout_s: float) -> None:
        """Switch a B unit's MDT693A compatibility mode (``cm=1`` / ``cm=0``), then read everything again.

        From then on the driver speaks the command set of the new mode (whatever ``command_set``
        said at construction). Outputs are not touched.

        Parameters
        ----------
        on
            True: the MDT693A command set; False: the unit's own.
        timeout_s
            Budget for the switch, s; the identity and limits are read again within ``timeout_s`` each.

        Raises
        ------
        ProtocolError
            The controller refused ``cm=`` (an MDT693A has no compatibility mode) or does not speak
            the requested command set afterwards.
        DeviceTimeout, DeviceDisconnected
            As for every exchange.
        """
        wanted = A_COMMANDS if on else B_COMMANDS
        with self._lock:
            deadline = time.monotonic() + timeout_s
            with self._guard(deadline):  # the reply may end in either mode's prompt
                self._exchange(encode_compatibility_mode(on), expect_body=False, deadline=deadline, prompts=PROMPTS)
            self.configured_command_set = wanted.name
            try:
                self._settle_command_set(timeout_s, wanted.name)
            except (ProtocolError, DeviceTimeout):
                self._needs_resync = True
                raise
            logger.info("%s: MDT693A compatibility mode %s", self.name, "on" if on else "off")

    # ----------------------------------------------------------------------------- internals
    def _check_axis(self, axis: str) -> None:
        if axis not in self.axes:
            raise ValueError(f"{self.name}: axis must be one of the configured {self.axes}, got {axis!r}")

    def _settle_command_set(self, timeout_s: float, command_set: str) -> None:
        """Synchronise, settle the command set (detect it for ``"auto"``), read identity and limits."""
        deadline = time.monotonic() + timeout_s
        if command_set != "auto":
            self._commands = COMMAND_SETS[command_set]
            self._resync(deadline)
        else:
            self._commands = B_COMMANDS
            probe = self._resync(deadline, probing=True)
            name = command_set_after_probe(probe, None)
            if name is None:
                answer = self._exchange(encode_command("cm?"), expect_body=True, deadline=deadline, prompts=PROMPTS,
                                        allow_error=True)
                name = command_set_after_probe(probe, answer)
            self._commands = COMMAND_SETS[name]
        body = self._command(self._commands.id_query, expect_body=True, deadline=time.monotonic() + timeout_s).body
        self._identity = identity = parse_id(body, device=self.name)
        missing = [axis for axis in self.axes if axis not in identity.axes]
        if missing:
            raise ProtocolError(self.name, f"axes {missing} are configured but an {identity.model} has only "
                                f"{identity.axes}")
        self._refresh_limits(time.monotonic() + timeout_s * (1 + 2 * len(self.axes)))

    def _refresh_limits(self, deadline: float) -> None:
        """Read ``vlimit?`` and each axis's min/max; recompute the effective limits."""
        with self._guard(deadline):
            commands = self._commands
            vlimit = parse_vlimit(self._command(commands.vlimit_query, expect_body=True, deadline=deadline).body,
                                  device=self.name)
            limits = {}
            for axis in self.axes:
                device_min = self._query_number(commands.min_query(axis), deadline)
                device_max = self._query_number(commands.max_query(axis), deadline)
                limits[axis] = _effective_limits(self.name, axis, software_min_v=self.software_min_v,
                                                 software_max_v=self.software_max_v, device_min_v=device_min,
                                                 device_max_v=device_max, vlimit_v=vlimit)
        self._vlimit_v, self._limits = vlimit, limits

    # ----------------------------------------------------------------------------- exchanges
    def _query_number(self, command: str, deadline: float) -> float:
        """Send a query and parse its numeric reply (bracketed or bare)."""
        return parse_number(self._command(command, expect_body=True, deadline=deadline).body, device=self.name)

    def _command(self, command: str | bytes, *, expect_body: bool, deadline: float, raw: bool = False) -> Reply:
        """Send one command (resynchronising first if due) and return its reply; ``raw``: already encoded."""
        with self._guard(deadline):
            data = command if raw else encode_command(command)
            assert isinstance(data, bytes)
            return self._exchange(data, expect_body=expect_body, deadline=deadline)

    @contextmanager
    def _guard(self, deadline: float) -> Iterator[None]:
        """Resync first if due (within ``deadline``); flag a resync after a garbled or missing reply."""
        self._link.require_open()
        try:
            if self._needs_resync:
                self._resync(deadline)
            yield
        except (ProtocolError, DeviceTimeout):
            self._needs_resync = True
            raise

    def _exchange(self, data: bytes, *, expect_body: bool, deadline: float, prompts: bytes | None = None,
                  allow_error: bool = False) -> Reply:
        """Write one command (stale input discarded first) and read its reply until the prompt.

        In the A command set an echo of the command may come first. ``allow_error``: return a
        rejection instead of raising :class:`ProtocolError`.
        """
        command = data.rstrip(b"\r")
        compat = self._commands is A_COMMANDS
        framing = partial(split_reply, echo_of=command if compat else None, expect_body=expect_body,
                          prompts=prompts or self._prompt, device=self.name, echo_optional=compat)
        reply = self._link.exchange(data, framing, deadline, during=repr(command.decode("ascii")), fresh=True)
        if reply.error is not None and not allow_error:
            raise ProtocolError(self.name, f"controller rejected {command.decode('ascii')!r}: {reply.error}"
                                f"{_MODE_HINT if reply.prompt == '!' and not compat else ''}")
        return reply

    def _resync(self, deadline: float, *, probing: bool = False) -> Reply:
        """Send ``echo=0`` (``%`` in the A set), wait for a prompt, then for the line to fall quiet.

        ``probing``: an ``!`` answer to ``echo=0`` is returned (it tells the command set) instead of
        raising. Returns the answer to the command sent.
        """
        compat = self._commands is A_COMMANDS
        reply = self._exchange(encode_command(A_COMMANDS.vlimit_query if compat else "echo=0"), expect_body=False,
                               deadline=deadline, prompts=PROMPTS, allow_error=probing)
        self._prompt = b"*" if compat or reply.prompt == "!" else reply.prompt.encode()
        self._link.drain(deadline)
        self._needs_resync = False
        logger.debug("%s: synchronised, prompt %r", self.name, self._prompt)
        return reply
