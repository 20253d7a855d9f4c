"""Driver for the Thorlabs MDT693B (3-axis) / MDT694B (1-axis) open-loop piezo controller.

The driver *has* a serial connection built with ``serial.serial_for_url``, so the same code runs on
``/dev/ttyUSB0``, ``COM3``, a pseudo-terminal path, ``socket://host:port`` and ``sim://mdt693b``.
Bytes are encoded and parsed by :mod:`wavestack.drivers.mdt693b.protocol` and the voltage limits
are combined by :mod:`wavestack.drivers.mdt693b.limits`; this module does the I/O, enforces the
limits and handles the errors.

On :meth:`MDT693B.open` the driver sends ``echo=0`` (the echo doubles the traffic and would need a
second parse path; whichever prompt, ``>`` or ``*``, ends that reply is the device's prompt from then
on), then reads ``id?``, ``vlimit?`` and ``<axis>min?``/``<axis>max?`` for every configured axis.
After a :class:`ProtocolError` or :class:`DeviceTimeout` the next command first resynchronises:
it flushes the input, sends ``echo=0`` again, waits for the prompt and for the line to fall quiet.
That also recovers a controller that was power-cycled (echo back on) behind the driver's back.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from types import TracebackType

import serial

from wavestack.drivers._checks import is_finite_real
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.mdt693b.limits import AxisLimits, _effective_limits, _on_wire
from wavestack.drivers.mdt693b.protocol import (
    AXES,
    PROMPTS,
    DeviceIdentity,
    Reply,
    encode_command,
    encode_set_voltage,
    parse_id,
    parse_number,
    parse_vlimit,
    split_reply,
)

__all__ = ["MDT693B", "AxisLimits", "VoltageReading"]

logger = logging.getLogger(__name__)

_POLL_S = 0.02  # serial read timeout: how often a waiting exchange checks its deadline
_QUIET_S = 0.05  # resync: the line counts as quiet after this long without a byte
_HARDWARE_MAX_V = 150.0


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


class MDT693B:
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
    ) -> None:
        axes = tuple(axes)
        if not axes or len(set(axes)) != len(axes) or not set(axes) <= set(AXES):
            raise ValueError(f"axes must be distinct members of {AXES}, got {axes!r}")
        if not 0.0 <= software_min_v < software_max_v <= _HARDWARE_MAX_V:
            raise ValueError(f"expected 0 <= software_min_v < software_max_v <= 150 V, "
                             f"got {software_min_v!r}, {software_max_v!r}")
        if not readback_tolerance_v > 0 or not timeout_s > 0:
            raise ValueError(f"readback_tolerance_v and timeout_s must be > 0, "
                             f"got {readback_tolerance_v!r}, {timeout_s!r}")
        self.url = url
        self.axes = axes
        self.software_min_v = float(software_min_v)
        self.software_max_v = float(software_max_v)
        self.readback_tolerance_v = float(readback_tolerance_v)
        self.timeout_s = float(timeout_s)
        self._lock = threading.RLock()
        self._port: serial.SerialBase | None = None
        self._lost: str | None = None
        self._needs_resync = False
        self._prompt = PROMPTS
        self._identity: DeviceIdentity | None = None
        self._vlimit_v = _HARDWARE_MAX_V
        self._limits: dict[str, AxisLimits] = {}

    # ------------------------------------------------------------------------------ lifecycle
    @property
    def name(self) -> str:
        """Who this is in messages: ``"MDT693B on /dev/ttyUSB0"``."""
        model = self._identity.model if self._identity is not None else "MDT693B"
        return f"{model} on {self.url}"

    @property
    def is_open(self) -> bool:
        """True between a successful :meth:`open` and :meth:`close` or a lost connection."""
        return self._port is not None

    def open(self, timeout_s: float | None = None) -> None:
        """Open the port, switch echo off, detect the prompt and read identity and limits.

        Parameters
        ----------
        timeout_s
            Per-exchange timeout, s (default: the constructor's ``timeout_s``).

        Raises
        ------
        ValueError
            The URL's scheme is unknown to pyserial (for ``sim://`` call
            ``register_serial_simulators()`` first).
        DeviceDisconnected
            The port cannot be opened.
        DeviceTimeout, ProtocolError
            The controller does not answer, or not like an MDT693B/694B; the port is closed again.
        """
        timeout = self.timeout_s if timeout_s is None else timeout_s
        with self._lock:
            if self._port is not None:
                return
            self._identity = None
            try:
                port = serial.serial_for_url(self.url, baudrate=115200, bytesize=8, parity="N", stopbits=1,
                                             timeout=_POLL_S, write_timeout=timeout)
            except ValueError as error:
                raise ValueError(f"{self.name}: cannot open {self.url!r} ({error}); for sim:// URLs call "
                                 "wavestack.simulators.serial_registry.register_serial_simulators() first") from None
            except (serial.SerialException, OSError) as error:
                raise DeviceDisconnected(self.name, f"cannot open the port ({error})") from error
            self._port, self._lost, self._needs_resync, self._prompt = port, None, False, PROMPTS
            try:
                self._handshake(timeout)
            except BaseException:
                self._close_port()
                raise
            logger.info("%s open: firmware %s, limit switch %.0f V, limits %s", self.name,
                        self._identity.firmware if self._identity else "?", self._vlimit_v,
                        {axis: (lim.min_v, lim.max_v) for axis, lim in self._limits.items()})

    def close(self) -> None:
        """Close the port; idempotent. Outputs stay where they are."""
        with self._lock:
            self._close_port()
            self._lost = None

    def __enter__(self) -> MDT693B:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    # ------------------------------------------------------------------------------ queries
    @property
    def identity(self) -> DeviceIdentity:
        """What ``id?`` reported at open; raises :class:`DeviceDisconnected` before."""
        with self._lock:
            self._require_open()
            if self._identity is None:  # unreachable: open() fails without an identity
                raise DeviceDisconnected(self.name, "no identity; call open() again")
            return self._identity

    @property
    def vlimit_v(self) -> float:
        """Front-panel limit switch as read at open (or the last limit refresh), V."""
        with self._lock:
            self._require_open()
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
            self._require_open()
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
            return self._query_number(f"{axis}voltage?", time.monotonic() + timeout_s)

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
            self._require_open()
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
            with self._guard(deadline):
                self._exchange(encode_set_voltage(axis, commanded), expect_body=False, deadline=deadline)
            readback = self._query_number(f"{axis}voltage?", deadline)
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

    # ----------------------------------------------------------------------------- internals
    def _check_axis(self, axis: str) -> None:
        if axis not in self.axes:
            raise ValueError(f"{self.name}: axis must be one of the configured {self.axes}, got {axis!r}")

    def _require_open(self) -> serial.SerialBase:
        if self._lost is not None:
            raise DeviceDisconnected(self.name, f"connection lost earlier ({self._lost}); call open() again")
        if self._port is None:
            raise DeviceDisconnected(self.name, "port is not open; call open() first")
        return self._port

    def _close_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError) as error:
                logger.debug("%s: error while closing (%s)", self.name, error)

    def _handshake(self, timeout_s: float) -> None:
        self._resync(time.monotonic() + timeout_s)
        body = self._command("id?", expect_body=True, deadline=time.monotonic() + timeout_s).body
        self._identity = identity = parse_id(body, device=self.name)
        missing = [axis for axis in self.axes if axis not in identity.axes]
        if missing:
            raise ProtocolError(self.name, f"axes {missing} are configured but an {identity.model} has only "
                                f"{identity.axes}")
        self._refresh_limits(time.monotonic() + timeout_s * (1 + 2 * len(self.axes)))

    def _refresh_limits(self, deadline: float) -> None:
        """Read ``vlimit?`` and each axis's min/max; recompute the effective limits."""
        with self._guard(deadline):
            vlimit = parse_vlimit(self._command("vlimit?", expect_body=True, deadline=deadline).body,
                                  device=self.name)
            limits = {}
            for axis in self.axes:
                device_min = self._query_number(f"{axis}min?", deadline)
                device_max = self._query_number(f"{axis}max?", deadline)
                limits[axis] = _effective_limits(self.name, axis, software_min_v=self.software_min_v,
                                                 software_max_v=self.software_max_v, device_min_v=device_min,
                                                 device_max_v=device_max, vlimit_v=vlimit)
        self._vlimit_v, self._limits = vlimit, limits

    def _query_number(self, command: str, deadline: float) -> float:
        with self._guard(deadline):
            return parse_number(self._command(command, expect_body=True, deadline=deadline).body, device=self.name)

    def _command(self, command: str, *, expect_body: bool, deadline: float) -> Reply:
        with self._guard(deadline):
            return self._exchange(encode_command(command), expect_body=expect_body, deadline=deadline)

    @contextmanager
    def _guard(self, deadline: float) -> Iterator[None]:
        """Resync first if due (within ``deadline``); flag a resync after a garbled or missing reply."""
        self._require_open()
        try:
            if self._needs_resync:
                self._resync(deadline)
            yield
        except (ProtocolError, DeviceTimeout):
            self._needs_resync = True
            raise

    @contextmanager
    def _port_io(self, during: str) -> Iterator[serial.SerialBase]:
        """The open port; serial failures become DeviceTimeout (write) or DeviceDisconnected (sticky)."""
        port = self._require_open()
        try:
            yield port
        except DeviceError:  # DeviceTimeout and DeviceDisconnected are OSErrors too: pass them through
            raise
        except serial.SerialTimeoutException as error:
            raise DeviceTimeout(self.name, f"writing {during} did not finish ({error})") from error
        except (serial.SerialException, OSError) as error:
            self._lost = f"{type(error).__name__}: {error}"
            self._close_port()
            raise DeviceDisconnected(self.name, f"serial port failed during {during} ({error})") from error

    def _exchange(self, data: bytes, *, expect_body: bool, deadline: float, prompts: bytes | None = None) -> Reply:
        """Write one command and read its reply until the prompt (caller holds the lock)."""
        command = data.rstrip(b"\r").decode("ascii")
        with self._port_io(repr(command)) as port:
            port.reset_input_buffer()
            port.write(data)
            buffer = b""
            while True:
                reply, _rest = split_reply(buffer, echo_of=None, expect_body=expect_body,
                                           prompts=prompts or self._prompt, device=self.name)
                if reply is not None:
                    break
                if time.monotonic() >= deadline:
                    raise DeviceTimeout(self.name, f"no complete reply to {command!r} before the deadline "
                                        f"(expected a reply ending in {self._prompt.decode()!r}, got {buffer[-40:]!r})")
                buffer += port.read(max(1, port.in_waiting))
        if reply.error is not None:
            raise ProtocolError(self.name, f"controller rejected {command!r}: {reply.error}")
        return reply

    def _resync(self, deadline: float) -> None:
        """Flush, send ``echo=0``, wait for a prompt and for the line to fall quiet."""
        reply = self._exchange(encode_command("echo=0"), expect_body=False, deadline=deadline, prompts=PROMPTS)
        self._prompt = reply.prompt.encode()
        with self._port_io("resynchronisation") as port:
            quiet_since = time.monotonic()
            while time.monotonic() - quiet_since < _QUIET_S and time.monotonic() < deadline:
                if port.read(max(1, port.in_waiting)):
                    quiet_since = time.monotonic()
            port.reset_input_buffer()
        self._needs_resync = False
        logger.debug("%s: synchronised, prompt %r", self.name, self._prompt)
