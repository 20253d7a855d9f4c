"""The polishing-station link: a Modbus/TCP client (pymodbus 3.16, sync) behind a small typed API.

:class:`PolishingLink` owns one :class:`~wavestack.drivers.plc.transport.ModbusTransport` (a
pymodbus ``ModbusTcpClient``) and adds what a closed loop needs from a PLC link:

- a heartbeat the host increments every cycle, with a check that the PLC logic echoes it, and the
  host's ownership of the PLC (:mod:`.heartbeat`);
- a command id / acknowledge handshake: a command takes effect once, when the PLC sees its id
  change; within one call a command whose reply was lost is resent with the same id (harmless);
- a gate before every command (:mod:`.gate`): a status read, and nothing is sent unless the PLC is
  scanning (echo fresh, also at the last heartbeat), ready, not busy, not tripped, no e-stop;
- the command the machine holds (:mod:`.commands`): a command whose fate is unknown after all
  retries is settled from the PLC's last accepted id before anything else is sent (nothing is sent
  while it cannot be); an unknown held command is read back from the output block;
- command limits (:class:`CommandLimits`: ``|removal|`` and the step from the held command), checked
  before the wire (:class:`CommandRefused`); :meth:`PolishingLink.restrict` only tightens them;
- jobs (:mod:`.job_control`): read the machine block, load and start a job file, behind the same gate;
- each result for the machine's panel (:meth:`PolishingLink.show_result`, the display block of
  :mod:`.display`), written by the owning link only;
- a start-up self-check of the float32 byte order that fails closed, and a write allow-list
  (:meth:`RegisterMap.check_write`) enforced before anything reaches the wire;
- typed errors (:mod:`wavestack.drivers.errors`) naming unit, register and function code:
  :class:`DeviceTimeout`, :class:`DeviceDisconnected`, :class:`ProtocolError`, :class:`PlcRefused`;
- after a timeout or a malformed reply the connection is closed (no stale bytes); the link
  reconnects on the next call with capped back-off, and the first request is the heartbeat.

Every public call takes ``timeout_s`` and never blocks longer. The class is thread-safe (one lock
around each call), so a station may run :meth:`heartbeat` from its own thread.

An error raised from a local (``stale = ...; raise stale``) drops the local in a ``finally``: else
the local, the error, its traceback and the frame form a cycle that only the cyclic garbage
collector frees, and until it runs the frames keep their callers' locals alive (the station's set
of camera frames and result, ~10 MB a cycle: +100 MB per frozen-echo fault in the soak, issue 13).
"""

from __future__ import annotations

import logging
import threading
import time
from types import TracebackType

import numpy as np
from numpy.typing import ArrayLike

from wavestack.drivers.errors import DeviceTimeout, ProtocolError
from wavestack.drivers.plc.commands import CommandLedger, CommandLimits, CommandRefused
from wavestack.drivers.plc.display import ResultDisplay, decode_display
from wavestack.drivers.plc.gate import (HeartbeatEchoStale, PlcNotReady, command_refusal, decode_self_check,
                                       no_scan_since, not_ready)
from wavestack.drivers.plc.heartbeat import HostHeartbeat, new_token
from wavestack.drivers.plc.job_control import JobControl
from wavestack.drivers.plc.jobs import JobLedger, JobLimits
from wavestack.drivers.plc.raw_access import RawAccess
from wavestack.drivers.plc.register_map import RegisterBlock, RegisterMap
from wavestack.drivers.plc.status import (
    CommandAck,
    MachineOutputs,
    PlcStatus,
    decode_outputs,
    decode_status,
    tripped_status,
)
from wavestack.drivers.plc.transport import LinkTiming, ModbusTransport, PlcRefused, deadline_after

__all__ = ["CommandLimits", "CommandRefused", "HeartbeatEchoStale", "LinkTiming", "PlcNotReady", "PlcRefused",
           "PolishingLink"]

_log = logging.getLogger(__name__)

_WATCHDOG_EXCEPTION = 4


class PolishingLink(HostHeartbeat, JobControl, RawAccess):
    """Modbus/TCP link to the polishing-station PLC.

    Commands publish the measured terms for the machine's display; removal happens only through
    jobs (:mod:`.job_control`). Raw register access for commissioning: :mod:`.raw_access`.

    Parameters
    ----------
    host, port
        Where the PLC (or its simulator) listens.
    register_map
        Addresses, function codes and byte orders (from the configuration).
    timing
        Timeouts, back-off and retry policy.
    command_limits
        Limits every removal command must meet (checked before the wire); None: none yet (a station
        sets them through :meth:`restrict` before its first command).
    monitor
        An operator's second client (``wavestack plc status|rearm``) while a station runs: it never
        writes the heartbeat (that would disturb the station's echo) and never sends a command.
    job_limits
        Limits every job must meet before the wire; None: loads are refused until :meth:`restrict_jobs`.

    Notes
    -----
    Typical use: ``connect``, ``self_check`` (fails closed on a wrong byte order), then per cycle
    ``heartbeat`` and, for a new measurement, ``send_removal(link.next_command_id(), removal_nm, ...)``.
    """

    def __init__(self, host: str, port: int, register_map: RegisterMap, timing: LinkTiming | None = None, *,
                 command_limits: CommandLimits | None = None, monitor: bool = False,
                 job_limits: JobLimits | None = None) -> None:
        if not 0 < port <= 65535:
            raise ValueError(f"port must be 1..65535, got {port}")
        self._map = register_map
        self._timing = timing or LinkTiming()
        self._device = f"PLC unit {register_map.unit_id} at {host}:{port}"
        self._lock = threading.RLock()
        self._monitor = monitor
        self._transport = ModbusTransport(host, port, register_map.unit_id, self._device, self._timing,
                                          on_connect=self._resume_heartbeat)
        self._beat = 0
        self._heartbeat_pending = True
        self._echo_stale = False
        self._echo_at_last_command: int | None = None  # the echo the gate saw before the last command
        self._self_check_passed = False
        self._sent_commands: dict[int, tuple[int, ...]] = {}
        self._limits = command_limits
        self._ledger = CommandLedger()
        self._jobs = JobLedger()
        self._job_limits = job_limits
        self._token = new_token()

    # ----------------------------------------------------------------------------- public API
    @property
    def device(self) -> str:
        """How errors name this PLC: ``"PLC unit 1 at 127.0.0.1:5020"``."""
        return self._device

    @property
    def register_map(self) -> RegisterMap:
        """The register map in use."""
        return self._map

    @property
    def connected(self) -> bool:
        """Whether a TCP connection is open now."""
        return self._transport.connected

    @property
    def reconnects(self) -> int:
        """Connections opened after the first one (after losses, timeouts or malformed replies)."""
        return self._transport.reconnects

    @property
    def command_limits(self) -> CommandLimits | None:
        """The limits every command is checked against (None: no host-side limits set)."""
        return self._limits

    def restrict(self, limits: CommandLimits) -> CommandLimits:
        """Tighten the command limits to the stricter of the old and ``limits`` (never loosened); returns them."""
        with self._lock:
            self._limits = limits.tightened(self._limits)
            return self._limits

    def next_command_id(self) -> int:
        """A fresh command id: after every id this link used or saw accepted, never the PLC's last accepted."""
        with self._lock:
            return self._ledger.next_id()

    def connect(self, timeout_s: float) -> PlcStatus:
        """Open the connection (with back-off until ``timeout_s``, else DeviceDisconnected), beat, read status."""
        deadline = deadline_after(timeout_s)
        with self._lock:
            self._transport.reset_backoff()
            self._transport.ensure_connected(deadline)
            return self._read_status(deadline)

    def self_check(self, timeout_s: float) -> float:
        """Read the known float32 constant and check it decodes with the configured byte order.

        Returns
        -------
        float
            The decoded constant.

        Raises
        ------
        ProtocolError
            The constant decodes to something else; the message names the configured word order and
            the order that would decode it. The link then refuses commands (fails closed).
        """
        deadline = deadline_after(timeout_s)
        block = self._map.self_check
        with self._lock:
            self._self_check_passed = False
            value = decode_self_check(self._device, block, self._read_block(block, deadline),
                                      self._map.self_check_value)
            self._self_check_passed = True
            _log.info("%s: self-check passed (%r with word order %s)", self._device, value, block.word_order)
            return value

    def send_removal(self, command_id: int, removal_nm: ArrayLike, passes: int, timeout_s: float) -> CommandAck:
        """Send one removal command and wait for the PLC to acknowledge its id.

        First the gate (status read), the settling of an unresolved command, a read-back of an
        unknown held command, and the limits against the held command; then the write.

        Parameters
        ----------
        command_id
            1..65535, new for every command (:meth:`next_command_id`); resending an id with the same
            values (a retry) never applies it twice.
        removal_nm
            Removal per term in nm, shape (n_terms,), already through the safety stage.
        passes
            Polishing passes, >= 1.
        timeout_s
            Budget for the whole exchange, retries included.

        Returns
        -------
        CommandAck
            The id, the number of sends it took and the confirming status.

        Raises
        ------
        ValueError
            Bad arguments; an id already sent with other values, or the PLC's last accepted id (a
            programming error, never a wire fault: use :meth:`next_command_id`). Nothing sent.
        CommandRefused
            Outside the :class:`CommandLimits`; nothing sent.
        PlcNotReady
            The gate: not scanning, tripped, e-stop, not ready or busy; nothing sent.
        ProtocolError
            The self-check has not passed, or the PLC did not acknowledge the id (then unresolved:
            the next call settles it from the PLC's status before sending anything).
        PlcRefused
            The PLC refused the command (3: a parameter out of range; 4: watchdog/e-stop; 6: busy).
        DeviceTimeout, DeviceDisconnected
            After the retries, or at once on a connection loss.
        """
        registers = tuple(self._map.encode_command(command_id, passes, removal_nm))
        values = np.asarray(removal_nm, dtype=np.float64)
        deadline = deadline_after(timeout_s)
        with self._lock:
            previous = self._sent_commands.get(command_id)
            if previous is not None and previous != registers:
                raise ValueError(f"{self._device}: command id {command_id} was already sent with other "
                                 "parameters; the PLC would ignore it (use a new id)")
            refusal = command_refusal(self._device, monitor=self._monitor, self_check_passed=self._self_check_passed,
                                      echo_stale=self._echo_stale)
            if refusal is not None:
                try:
                    raise refusal
                finally:  # no cycle with this frame (module notes)
                    del refusal
            self._transport.ensure_connected(deadline)
            if self._heartbeat_pending:
                self._send_heartbeat(deadline)  # heartbeat resumes before any command
            held = self._gate(command_id, deadline)
            if previous is None and command_id == self._ledger.plc_accepted:
                raise ValueError(f"{self._device}: command id {command_id} is the PLC's last accepted id; it would "
                                 "ignore it (use next_command_id())")
            if self._limits is not None and (previous is None or self._ledger.held_id != command_id):
                why = self._limits.violation(values, held)
                if why is not None:
                    raise CommandRefused(self._device, f"command {command_id} refused before the wire: {why}")
            self._sent_commands = {command_id: registers}  # only the latest id matters for retries
            self._ledger.sending(command_id, values)
            attempts = self._write_command(command_id, registers, deadline)
            status = self._read_status(deadline)
            if status.last_accepted_id != command_id:
                raise ProtocolError(self._device, f"command {command_id} was written but the PLC reports last "
                                    f"accepted id {status.last_accepted_id} (register {self._map.status.start + 1})")
            self._ledger.accepted()
            return CommandAck(command_id=command_id, attempts=attempts, status=status)

    def show_result(self, display: ResultDisplay, timeout_s: float) -> None:
        """Write one result into the display block, whole, in one FC16 request, for the machine's panel.

        The block is the owner's, as the heartbeat is: a monitor link never writes it. It is no
        command (nothing moves on it), so there is no gate and no handshake; any client reads it.

        Raises
        ------
        ValueError
            The map has no display block, or a figure beyond float32 (nothing sent).
        ProtocolError
            On a monitor link (nothing sent).
        PlcRefused
            1: another connection owns the PLC; 4: the watchdog has tripped.
        DeviceTimeout, DeviceDisconnected
            The write got no reply in time, or the connection was lost.
        """
        registers = self._map.encode_display(display)
        block = self._map.display
        assert block is not None  # encode_display refuses a map without one
        deadline = deadline_after(timeout_s)
        with self._lock:
            if self._monitor:
                raise ProtocolError(self._device, "a monitor link writes no display block (the station owns it)")
            self._transport.ensure_connected(deadline)
            self._write(block.start, registers, block.write_function or 16, deadline)

    def read_display(self, timeout_s: float) -> ResultDisplay | None:
        """The result the machine's panel shows (any link may read it); None when the map has no display block.

        Raises
        ------
        PlcRefused
            4 while the watchdog is tripped (the PLC answers nothing else).
        ProtocolError
            The block holds a code outside the code tables.
        """
        block = self._map.display
        if block is None or block.word_order is None:
            return None
        deadline = deadline_after(timeout_s)
        with self._lock:
            registers = self._read_block(block, deadline)
        try:
            return decode_display(registers, block.word_order)
        except ValueError as error:
            raise ProtocolError(self._device, f"{error} (registers {block.start}-{block.stop - 1})") from None

    def read_status(self, timeout_s: float) -> PlcStatus:
        """The status block; a tripped watchdog (exception 4) is reported as ``watchdog_tripped``."""
        deadline = deadline_after(timeout_s)
        with self._lock:
            self._transport.ensure_connected(deadline)
            return self._read_status(deadline)

    def held_removal(self, timeout_s: float) -> np.ndarray:
        """What the machine holds (nm per term), after settling a command whose reply was lost.

        Reads the status (a lost command the PLC accepted is then held) and, when the held command is
        unknown, the output block. Raises a DeviceError when it cannot tell: then send nothing.
        """
        deadline = deadline_after(timeout_s)
        with self._lock:
            return self._settle(self._read_status(deadline), deadline).copy()

    def read_outputs(self, timeout_s: float) -> MachineOutputs:
        """The machine outputs (read-only block the watchdog zeroes); PlcRefused (4) while tripped."""
        deadline = deadline_after(timeout_s)
        block = self._map.output
        with self._lock:
            registers = self._read_block(block, deadline)
            assert block.word_order is not None
            return decode_outputs(registers, block.word_order)

    def close(self) -> None:
        """Close the connection; idempotent. A later call reconnects."""
        with self._lock:
            self._transport.close()
            self._heartbeat_pending = True

    def __enter__(self) -> PolishingLink:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    # ----------------------------------------------------------------------------- internals
    def _gate(self, command_id: int, deadline: float) -> np.ndarray:
        """Read the status; refuse unless the PLC can take a command; settle the held command; return it."""
        status = self._read_status(deadline)
        stale = self._echo_lag_error(status)
        if stale is not None:
            self._echo_stale = True
            raise PlcNotReady(self._device, f"refusing command {command_id}: {stale.detail}")
        why = no_scan_since(self._echo_at_last_command, self._beat, status) or not_ready(status)
        if why is not None:
            raise PlcNotReady(self._device, f"refusing command {command_id}: the PLC is {why}")
        self._echo_at_last_command = status.heartbeat_echo
        return self._settle(status, deadline)

    def _settle(self, status: PlcStatus, deadline: float) -> np.ndarray:
        """Settle an unresolved command from ``status``, read back an unknown held command; the held values."""
        settled = self._ledger.resolve(status.last_accepted_id)
        if settled is not None:
            _log.warning("%s: %s", self._device, settled)
        if self._ledger.needs_read_back(status.last_accepted_id):
            block = self._map.output
            assert block.word_order is not None
            outputs = decode_outputs(self._read_block(block, deadline), block.word_order)
            self._ledger.read_back(status.last_accepted_id, outputs.setpoint_nm)
            _log.info("%s: the machine holds %s nm (read back)", self._device, outputs.setpoint_nm.tolist())
        assert self._ledger.held_nm is not None
        return self._ledger.held_nm

    def _write_command(self, command_id: int, registers: tuple[int, ...], deadline: float) -> int:
        """Write the command block, resending the same id after a timeout or malformed reply; the attempts."""
        attempts = 0
        while True:
            attempts += 1
            try:
                self._transport.ensure_connected(deadline)
                self._write(self._map.command.start, list(registers), self._map.command.write_function or 16,
                            deadline)
                return attempts
            except PlcRefused:
                self._sent_commands = {}  # refused, never accepted: the id may be reused
                self._ledger.refused()
                raise
            except (DeviceTimeout, ProtocolError) as error:
                if attempts > self._timing.command_retries or time.monotonic() >= deadline:
                    raise
                _log.warning("%s: command %d, attempt %d failed (%s); resending the same id",
                             self._device, command_id, attempts, error.detail)

    def _read_status(self, deadline: float) -> PlcStatus:
        try:
            status = decode_status(self._read_block(self._map.status, deadline))
        except PlcRefused as error:
            if error.exception_code == _WATCHDOG_EXCEPTION:
                self._ledger.invalidate()  # the watchdog zeroes the outputs
                return tripped_status()
            raise
        self._ledger.saw_accepted_id(status.last_accepted_id)
        return status

    def _read_block(self, block: RegisterBlock, deadline: float) -> list[int]:
        self._transport.ensure_connected(deadline)
        return self._transport.read(block.start, block.count, block.read_function, deadline)

    def _write(self, address: int, values: list[int], function_code: int, deadline: float) -> None:
        self._map.check_write(address, len(values), function_code)  # the allow-list, before the wire
        try:
            self._transport.write(address, values, function_code, deadline)
        except PlcRefused as error:
            if error.exception_code == _WATCHDOG_EXCEPTION:
                self._ledger.invalidate()  # tripped (outputs zeroed) or e-stop: read the outputs back
            raise

