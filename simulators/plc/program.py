"""The simulated PLC's program: ownership, watchdog, command handshake, jobs, status and outputs.

Re-implemented from the register-map description in the README, without importing the driver's
codec or map (a shared misunderstanding must not make both ends agree). The program is evaluated
once per Modbus request (a "scan" per request) and whenever a test reads its ground truth, with
the caller's clock, so no timer task is needed. It knows nothing about sockets: the server hands it
each request's address and written values and lets it mirror its state into pymodbus's memory.

Rules:

- writes: one connection owns the heartbeat, command, job and display blocks (:mod:`.ownership`): the first
  that claims it (with the owner block's token, or by the first heartbeat on a map without one),
  until the watchdog trips; another connection's write there answers exception 1 (illegal
  function: not for this connection); the re-arm register takes anyone's write (the operator's);
- the watchdog (:class:`HeartbeatWatchdog`) counts only a *change* of the heartbeat register;
  tripped, it zeroes the outputs, ends the ownership, and every request but a write of 1 to the
  re-arm register is answered with exception 4;
- a write that changes the command id (to non-zero) shows the command once on the
  :class:`PolishingStation`'s display (the measured terms; it removes nothing: removal happens only
  through jobs); parameters it refuses answer exception 3 and change nothing; before the first
  heartbeat or with the e-stop pressed, exception 4; while busy, exception 6;
- a write of the job block (if configured) hands its action to the :class:`PolishingMachine`:
  LOAD and START answer exception 4 before the first heartbeat or with the e-stop pressed, 6 while
  busy (a pass, or LOAD while a job runs), 3 for a START or ABORT of a job not loaded; ABORT is
  always taken. The watchdog tripping, the e-stop and a restart stop a running job (ABORTED);
- the machine block mirrors the machine's state, reason, job id, points done and point count;
- the display block (if configured) keeps what the owner last wrote there, whole, for any client to
  read (the panel's HMI); the watchdog tripping zeroes it (result invalid, no verdict), as it
  zeroes the outputs: a host that stopped must not leave its last verdict on the panel;
- the status block holds the status word (bit 0 ready, 1 busy, 2 fault, 3 e-stop, 4 heartbeat
  seen), the last accepted id and the heartbeat echo (frozen by the ``freeze_heartbeat_echo`` fault).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from pymodbus.constants import ExcCodes

from wavestack.simulators.plc.faults import SimFaults
from wavestack.simulators.plc.layout import DISPLAY_COUNT, JOB_COUNT, MACHINE_COUNT, OWNER_COUNT, PlcSimLayout
from wavestack.simulators.plc.job_state import StopReason
from wavestack.simulators.plc.machine import PolishingMachine
from wavestack.simulators.plc.ownership import NOBODY, Ownership, claim, closed, first_heartbeat, owns
from wavestack.simulators.plc.polishing import PolishingStation, RemovalCommand
from wavestack.simulators.plc.watchdog import HeartbeatWatchdog, WatchdogState
from wavestack.simulators.plc.words import float_to_words, uint32_to_words, words_to_float, words_to_uint32

__all__ = ["HISTORY_LENGTH", "PolishingPlcProgram", "SimOutputs", "float_to_words", "words_to_float"]

_LOAD, _START, _ABORT = 1, 2, 3

#: Accepted commands the program remembers for tests (the newest; a long run must not grow without bound).
HISTORY_LENGTH = 10_000

_log = logging.getLogger(__name__)

_READY, _BUSY, _FAULT, _ESTOP, _HEARTBEAT_SEEN = 1, 2, 4, 8, 16


@dataclass(frozen=True)
class SimOutputs:
    """Ground truth of the machine outputs; ``setpoint_nm`` has shape (n_terms,), nm."""

    spindle_enabled: bool
    active_command_id: int
    setpoint_nm: NDArray[np.float64] = field(repr=False)

    @property
    def all_zero(self) -> bool:
        """Every output is zero."""
        return not self.spindle_enabled and self.active_command_id == 0 and not np.any(self.setpoint_nm)


class PolishingPlcProgram:
    """State and rules of the simulated PLC; thread-safe (the server thread and tests share it).

    Parameters
    ----------
    layout
        Register layout and watchdog timeout.
    station
        The polishing model commands act on.
    faults
        Fault switches (e-stop, frozen heartbeat echo) the program consults.
    machine
        The polishing machine the job block drives (None: job writes answer exception 4).
    """

    def __init__(self, layout: PlcSimLayout, station: PolishingStation, faults: SimFaults,
                 machine: PolishingMachine | None = None) -> None:
        if station.n_terms != layout.n_terms:
            raise ValueError(f"the station has {station.n_terms} terms but the command block carries {layout.n_terms}")
        self.layout = layout
        self.station = station
        self.faults = faults
        self.machine = machine
        self._lock = threading.Lock()
        self._job_regs = [0] * JOB_COUNT
        self._display_regs = [0] * DISPLAY_COUNT
        self._watchdog = HeartbeatWatchdog(layout.watchdog_timeout_s)
        self._echo = 0
        self._rearm_value = 0
        self._command_regs = [0] * layout.command_block[1]
        self._last_accepted = 0
        self._fault_latched = False
        self._busy_until = 0.0
        self._outputs = self._zero_outputs()
        self._accepted: deque[int] = deque(maxlen=HISTORY_LENGTH)
        self._accepted_removals: deque[tuple[float, ...]] = deque(maxlen=HISTORY_LENGTH)
        self._accepted_count = 0
        self._owner: Ownership = NOBODY

    # ----------------------------------------------------------------------------- ground truth
    @property
    def owner_connection(self) -> int | None:
        """The connection that owns the PLC now (None: nobody, or the owner is between connections)."""
        with self._lock:
            return self._owner.connection

    def connection_closed(self, connection: int) -> None:
        """A connection closed: if it owned the PLC, the place waits for its token (module notes)."""
        with self._lock:
            self._owner = closed(self._owner, connection)

    def watchdog_state(self, now: float) -> WatchdogState:
        """The watchdog's state at ``now``."""
        with self._lock:
            self._scan(now)
            return self._watchdog.state

    def watchdog_trips(self, now: float) -> int:
        """How many times the watchdog has tripped up to ``now``."""
        with self._lock:
            self._scan(now)
            return self._watchdog.trips

    def outputs(self, now: float) -> SimOutputs:
        """The machine outputs at ``now``."""
        with self._lock:
            self._scan(now)
            return self._outputs

    @property
    def last_accepted_id(self) -> int:
        """Id of the last accepted command (0 = none)."""
        with self._lock:
            return self._last_accepted

    @property
    def accepted_commands(self) -> list[int]:
        """Ids of the commands that took effect, in order (the last :data:`HISTORY_LENGTH`)."""
        with self._lock:
            return list(self._accepted)

    @property
    def accepted_removals(self) -> list[tuple[float, ...]]:
        """The removal (nm per term) of the commands that took effect, in order (the last :data:`HISTORY_LENGTH`)."""
        with self._lock:
            return list(self._accepted_removals)

    @property
    def accepted_count(self) -> int:
        """Commands that took effect since start (all of them, not only the remembered ones)."""
        with self._lock:
            return self._accepted_count

    @property
    def heartbeat_value(self) -> int:
        """The last heartbeat value the watchdog saw."""
        with self._lock:
            return self._watchdog.value

    # ----------------------------------------------------------------------------- one request
    def on_request(self, address: int, written: list[int] | None, now: float, start_address: int,
                   registers: list[int], connection: int = 0) -> ExcCodes | None:
        """Run one scan for a request and mirror the state into pymodbus's ``registers``.

        Parameters
        ----------
        address
            First register of the request.
        written
            Values a write request carries, None for a read.
        now
            The clock, s.
        start_address, registers
            pymodbus's register memory (shared block) and the address of its first entry.
        connection
            Which connection sent the request (the server numbers them).

        Returns
        -------
        ExcCodes | None
            The exception to answer, or None for a normal reply.
        """
        with self._lock:
            self._scan(now)
            result = self._handle(address, written, now, connection)
            self._mirror(start_address, registers, now)
            return result

    # ----------------------------------------------------------------------------- rules (lock held)
    def _zero_outputs(self) -> SimOutputs:
        return SimOutputs(False, 0, np.zeros(self.layout.n_terms))

    def interlock(self, now: float) -> StopReason | None:
        """Why a running job must stop now (e-stop, watchdog not running), or None; for the machine's thread."""
        with self._lock:
            self._scan(now)
            if self.faults.estop:
                return StopReason.ESTOP
            return None if self._watchdog.state is WatchdogState.RUNNING else StopReason.WATCHDOG

    def power_cycle(self, now: float) -> None:
        """The PLC program restarts: a running job stops (PLC_RESTART), the watchdog waits for a heartbeat."""
        if self.machine is not None:
            self.machine.stop(StopReason.PLC_RESTART)
        with self._lock:
            self._watchdog = HeartbeatWatchdog(self.layout.watchdog_timeout_s, self._watchdog.value)
            self._owner = NOBODY
            self._outputs = self._zero_outputs()
            self._display_regs = [0] * DISPLAY_COUNT
            self._busy_until = now

    def _scan(self, now: float) -> None:
        if self._watchdog.poll(now):
            if self.machine is not None:
                self.machine.stop(StopReason.WATCHDOG)
            self._outputs = self._zero_outputs()
            self._display_regs = [0] * DISPLAY_COUNT
            self._owner = NOBODY
            _log.warning("PLC simulator: watchdog tripped (no heartbeat change for %.3f s); outputs zeroed",
                         self.layout.watchdog_timeout_s)

    def _handle(self, address: int, values: list[int] | None, now: float, connection: int) -> ExcCodes | None:
        layout = self.layout
        written = dict(zip(range(address, address + len(values)), values)) if values is not None else {}
        if self._watchdog.state is WatchdogState.TRIPPED:
            if written.get(layout.rearm_register) == 1:
                self._watchdog.rearm(now)
                self._rearm_value = 1
                _log.warning("PLC simulator: watchdog re-armed")
                return None
            return ExcCodes.DEVICE_FAILURE
        refusal = self._check_owner(written, connection)
        if refusal is not None:
            return refusal
        if layout.heartbeat_register in written:
            beat = written[layout.heartbeat_register]
            self._watchdog.observe(beat, now)
            if not self.faults.freeze_heartbeat_echo:
                self._echo = beat
        if layout.rearm_register in written:
            self._rearm_value = written[layout.rearm_register]
        start, count = layout.command_block
        if any(start <= a < start + count for a in written):
            merged = list(self._command_regs)
            for a, v in written.items():
                if start <= a < start + count:
                    merged[a - start] = v
            if start in written and merged[0] not in (0, self._last_accepted):
                refusal = self._accept(merged, now)
                if refusal is not None:
                    return refusal
            self._command_regs = merged
        if layout.job_register is not None and layout.job_register in written:
            regs = [written.get(layout.job_register + i, 0) for i in range(JOB_COUNT)]
            refusal = self._job_action(regs, now)
            if refusal is not None:
                return refusal
            self._job_regs = regs
        if layout.display_register is not None and layout.display_register in written:
            self._display_regs = [written.get(layout.display_register + i, 0) for i in range(DISPLAY_COUNT)]
        return None

    def _check_owner(self, written: dict[int, int], connection: int) -> ExcCodes | None:
        """Claims through the owner block; exception 1 for a write only the owner may make (module notes)."""
        layout = self.layout
        if layout.owner_register is not None and layout.owner_register in written:
            token = tuple(written.get(layout.owner_register + i, 0) for i in range(OWNER_COUNT))
            self._owner, taken = claim(self._owner, connection, token)
            if not taken:
                _log.warning("PLC simulator: connection %d claimed with a token that is not the owner's: refused",
                             connection)
                return ExcCodes.ILLEGAL_FUNCTION
        start, count = layout.command_block
        owner_only = [a for a in written if a == layout.heartbeat_register or start <= a < start + count
                      or _within(a, layout.job_register, JOB_COUNT) or _within(a, layout.display_register, DISPLAY_COUNT)]
        if not owner_only:
            return None
        if layout.owner_register is None and layout.heartbeat_register in written:
            self._owner = first_heartbeat(self._owner, connection)
        if not owns(self._owner, connection):
            _log.warning("PLC simulator: connection %d wrote register %d, which only the owner may write: refused",
                         connection, owner_only[0])
            return ExcCodes.ILLEGAL_FUNCTION
        return None

    def _job_action(self, registers: list[int], now: float) -> ExcCodes | None:
        action, job_id = registers[0], registers[1]
        if self.machine is None or action not in (_LOAD, _START, _ABORT):
            return ExcCodes.ILLEGAL_VALUE if self.machine is not None else ExcCodes.DEVICE_FAILURE
        if action == _ABORT:
            return None if self.machine.abort(job_id) else ExcCodes.ILLEGAL_VALUE
        if self.faults.estop or self._watchdog.state is not WatchdogState.RUNNING:
            _log.warning("PLC simulator: job action %d refused with exception 4 (e-stop or no heartbeat)", action)
            return ExcCodes.DEVICE_FAILURE
        if now < self._busy_until or job_id == 0:
            return ExcCodes.DEVICE_BUSY if job_id else ExcCodes.ILLEGAL_VALUE
        if action == _START:
            return None if self.machine.start(job_id) else ExcCodes.ILLEGAL_VALUE
        order = self.layout.job_order
        crc = words_to_uint32(registers[2:4], order)
        count = words_to_uint32(registers[4:6], order)
        total = words_to_float(registers[6:8], order)
        return None if self.machine.load(job_id, crc, count, total) else ExcCodes.DEVICE_BUSY

    def _accept(self, registers: list[int], now: float) -> ExcCodes | None:
        command_id, passes = registers[0], registers[1]
        if self.faults.estop or self._watchdog.state is not WatchdogState.RUNNING:
            _log.warning("PLC simulator: command %d refused with exception 4 (e-stop or no heartbeat)", command_id)
            return ExcCodes.DEVICE_FAILURE
        if now < self._busy_until:
            return ExcCodes.DEVICE_BUSY
        order = self.layout.command_word_order
        removal = [words_to_float(registers[i:i + 2], order) for i in range(2, len(registers), 2)]
        command = RemovalCommand(command_id=command_id, removal_nm=tuple(removal), passes=passes)
        try:
            self.station.display(command)
        except ValueError as error:
            self._fault_latched = True
            _log.warning("PLC simulator: command %d refused with exception 3: %s", command_id, error)
            return ExcCodes.ILLEGAL_VALUE
        self._last_accepted = command_id
        self._accepted.append(command_id)
        self._accepted_removals.append(tuple(removal))
        self._accepted_count += 1
        self._fault_latched = False
        self._busy_until = now + passes * self.layout.pass_duration_s
        self._outputs = SimOutputs(True, command_id, np.asarray(removal, dtype=np.float64))
        return None

    def _status_word(self, now: float) -> int:
        running = self._watchdog.state is WatchdogState.RUNNING
        busy = now < self._busy_until
        estop = self.faults.estop
        word = (_BUSY if busy else 0) | (_ESTOP if estop else 0) | (_HEARTBEAT_SEEN if running else 0)
        word |= _FAULT if (self._fault_latched or estop) else 0
        word |= _READY if running and not busy and not estop else 0
        return word

    def _mirror(self, start_address: int, registers: list[int], now: float) -> None:
        """Write the program's state into pymodbus's memory (which a server restart rebuilds empty)."""
        layout = self.layout

        def put(address: int, values: list[int]) -> None:
            registers[address - start_address:address - start_address + len(values)] = values

        put(layout.heartbeat_register, [self._watchdog.value])
        put(layout.rearm_register, [self._rearm_value])
        put(layout.status_register, [self._status_word(now), self._last_accepted, self._echo])
        put(layout.command_block[0], self._command_regs)
        setpoints: list[int] = []
        for value in self._outputs.setpoint_nm:
            setpoints.extend(float_to_words(float(value), layout.output_word_order))
        put(layout.output_block[0], [int(self._outputs.spindle_enabled), self._outputs.active_command_id, *setpoints])
        if layout.job_register is not None and layout.machine_register is not None:
            put(layout.job_register, self._job_regs)
            put(layout.machine_register, self._machine_words())
        if layout.owner_register is not None:
            put(layout.owner_register, [0] * OWNER_COUNT)  # write-only: a token is never read back
        if layout.display_register is not None:
            put(layout.display_register, self._display_regs)

    def _machine_words(self) -> list[int]:
        if self.machine is None:
            return [0] * MACHINE_COUNT
        snap = self.machine.snapshot()
        order = self.layout.job_order
        return [int(snap.state), int(snap.reason), snap.job_id, *uint32_to_words(snap.points_done, order),
                *uint32_to_words(snap.point_count, order)]


def _within(address: int, start: int | None, count: int) -> bool:
    """Whether ``address`` lies in the optional block ``[start, start + count)``."""
    return start is not None and start <= address < start + count
