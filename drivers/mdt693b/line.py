"""The serial line to one MDT693B / MDT694B / MDT693A: command exchanges, resynchronisation, loss.

:class:`ControllerLine` *has* the port (``serial.serial_for_url``) and knows only framing: it writes a
command, reads until the prompt with :func:`~wavestack.drivers.mdt693b.protocol.split_reply`, turns
serial failures into typed errors (a lost port stays lost until reopened) and resynchronises after a
garbled or missing reply. What the commands mean is the driver's business
(:mod:`~wavestack.drivers.mdt693b.driver`). The caller serialises access (the driver's lock).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import serial

from wavestack.drivers.device_path import check_device_path
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, ProtocolError
from wavestack.drivers.mdt693b.command_sets import A_COMMANDS, B_COMMANDS, CommandSet
from wavestack.drivers.mdt693b.protocol import PROMPTS, Reply, encode_command, parse_number, split_reply

__all__ = ["ControllerLine"]

logger = logging.getLogger(__name__)

_POLL_S = 0.02  # serial read timeout: how often a waiting exchange checks its deadline
_QUIET_S = 0.05  # resync: the line counts as quiet after this long without a byte
_MODE_HINT = (" (an MDT693A answer: the controller speaks the MDT693A command set, its compatibility mode is "
              "on; construct the driver with command_set='auto' or 'mdt693a', or switch the mode off)")


class ControllerLine:
    """Command exchanges with one controller over ``serial.serial_for_url(url)``.

    Parameters
    ----------
    url
        Anything ``serial.serial_for_url`` opens.
    name
        Returns who the controller is, for messages (the driver's name, which changes once the
        identity is known).

    Attributes
    ----------
    commands
        The command set in use; in the MDT693A set an echo is accepted, not switched off, and the
        resynchronisation sends ``%`` instead of ``echo=0``.
    needs_resync
        True after a garbled or missing reply: the next guarded exchange resynchronises first.
    """

    def __init__(self, url: str, name: Callable[[], str]) -> None:
        self.url = url
        self._name = name
        self.commands: CommandSet = B_COMMANDS
        self.needs_resync = False
        self._port: serial.SerialBase | None = None
        self._lost: str | None = None
        self._prompt = PROMPTS

    @property
    def is_open(self) -> bool:
        """True while the port is open (not after :meth:`close` or a lost connection)."""
        return self._port is not None

    def open(self, write_timeout_s: float) -> None:
        """Open the port at 115200 8N1.

        Raises
        ------
        ValueError
            The URL's scheme is unknown to pyserial, or a local path that is not a serial port or
            terminal once resolved (checked again here, just before opening: a symlink may have
            changed since the configuration was read; see :mod:`wavestack.drivers.device_path`).
        DeviceDisconnected
            The port cannot be opened.
        """
        refusal = check_device_path(self.url) if "://" not in self.url else None
        if refusal is not None:
            raise ValueError(f"{self._name()}: refusing to open {self.url!r}: {refusal}")
        try:
            port = serial.serial_for_url(self.url, baudrate=115200, bytesize=8, parity="N", stopbits=1,
                                         timeout=_POLL_S, write_timeout=write_timeout_s)
        except ValueError as error:
            raise ValueError(f"{self._name()}: cannot open {self.url!r} ({error}); for sim:// URLs call "
                             "wavestack.simulators.serial_registry.register_serial_simulators() first") from None
        except (serial.SerialException, OSError) as error:
            raise DeviceDisconnected(self._name(), f"cannot open the port ({error})") from error
        self._port, self._lost, self.needs_resync, self._prompt = port, None, False, PROMPTS

    def close(self, *, forget_loss: bool = True) -> None:
        """Close the port; idempotent. ``forget_loss``: a later call no longer reports an earlier loss."""
        port, self._port = self._port, None
        if forget_loss:
            self._lost = None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError) as error:
                logger.debug("%s: error while closing (%s)", self._name(), error)

    def require_open(self) -> serial.SerialBase:
        """The open port; :class:`DeviceDisconnected` when closed or lost."""
        if self._lost is not None:
            raise DeviceDisconnected(self._name(), f"connection lost earlier ({self._lost}); call open() again")
        if self._port is None:
            raise DeviceDisconnected(self._name(), "port is not open; call open() first")
        return self._port

    def query_number(self, command: str, deadline: float) -> float:
        """Send a query and parse its numeric reply (bracketed or bare)."""
        with self.guard(deadline):
            return parse_number(self.command(command, expect_body=True, deadline=deadline).body, device=self._name())

    def command(self, command: str, *, expect_body: bool, deadline: float) -> Reply:
        """Send one command (resynchronising first if due) and return its reply."""
        with self.guard(deadline):
            return self.exchange(encode_command(command), expect_body=expect_body, deadline=deadline)

    @contextmanager
    def guard(self, deadline: float) -> Iterator[None]:
        """Resync first if due (within ``deadline``); flag a resync after a garbled or missing reply."""
        self.require_open()
        try:
            if self.needs_resync:
                self.resync(deadline)
            yield
        except (ProtocolError, DeviceTimeout):
            self.needs_resync = True
            raise

    def exchange(self, data: bytes, *, expect_body: bool, deadline: float, prompts: bytes | None = None,
                 allow_error: bool = False) -> Reply:
        """Write one command and read its reply until the prompt.

        In the A command set an echo of the command may come first (:func:`split_reply` with
        ``echo_optional``). ``allow_error``: return a rejection instead of raising
        :class:`ProtocolError`.
        """
        command = data.rstrip(b"\r").decode("ascii")
        compat = self.commands is A_COMMANDS
        with self._port_io(repr(command)) as port:
            port.reset_input_buffer()
            port.write(data)
            buffer = b""
            while True:
                reply, _rest = split_reply(buffer, echo_of=data.rstrip(b"\r") if compat else None,
                                           expect_body=expect_body, prompts=prompts or self._prompt,
                                           device=self._name(), echo_optional=compat)
                if reply is not None:
                    break
                if time.monotonic() >= deadline:
                    raise DeviceTimeout(self._name(), f"no complete reply to {command!r} before the deadline "
                                        f"(expected a reply ending in {self._prompt.decode()!r}, got {buffer[-40:]!r})")
                buffer += port.read(max(1, port.in_waiting))
        if reply.error is not None and not allow_error:
            raise ProtocolError(self._name(), f"controller rejected {command!r}: {reply.error}"
                                f"{_MODE_HINT if reply.prompt == '!' and not compat else ''}")
        return reply

    def resync(self, deadline: float, *, probing: bool = False) -> Reply:
        """Flush, send ``echo=0`` (``%`` in the A set), wait for a prompt and for the line to fall quiet.

        ``probing``: an ``!`` answer to ``echo=0`` is returned (it tells the command set) instead of
        raising. Returns the answer to the command sent.
        """
        compat = self.commands is A_COMMANDS
        reply = self.exchange(encode_command(A_COMMANDS.vlimit_query if compat else "echo=0"),
                              expect_body=False, deadline=deadline, prompts=PROMPTS, allow_error=probing)
        self._prompt = b"*" if compat or reply.prompt == "!" else reply.prompt.encode()
        with self._port_io("resynchronisation") as port:
            quiet_since = time.monotonic()
            while time.monotonic() - quiet_since < _QUIET_S and time.monotonic() < deadline:
                if port.read(max(1, port.in_waiting)):
                    quiet_since = time.monotonic()
            port.reset_input_buffer()
        self.needs_resync = False
        logger.debug("%s: synchronised, prompt %r", self._name(), self._prompt)
        return reply

    @contextmanager
    def _port_io(self, during: str) -> Iterator[serial.SerialBase]:
        """The open port; serial failures become DeviceTimeout (write) or DeviceDisconnected (sticky)."""
        port = self.require_open()
        try:
            yield port
        except DeviceError:  # DeviceTimeout and DeviceDisconnected are OSErrors too: pass them through
            raise
        except serial.SerialTimeoutException as error:
            raise DeviceTimeout(self._name(), f"writing {during} did not finish ({error})") from error
        except (serial.SerialException, OSError) as error:
            self._lost = f"{type(error).__name__}: {error}"
            self.close(forget_loss=False)
            raise DeviceDisconnected(self._name(), f"serial port failed during {during} ({error})") from error
