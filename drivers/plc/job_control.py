"""The job verbs of :class:`~wavestack.drivers.plc.driver.PolishingLink`: read the machine, load, start, abort.

A mixin, so that the link's module stays short; it uses the link's lock, transport, heartbeat and
gate. Every verb that moves the machine passes the same checks as a removal command, before the
wire: not a monitor link, the self-check passed, the heartbeat echoed (the PLC is scanning, also
since the last command or job write), not tripped, no e-stop, not busy (a pass, or a running job);
and a load passes the :class:`~wavestack.drivers.plc.jobs.JobLimits` and the job-id ledger (an id
is spent once this host announced it, whatever the machine answers, or once the machine reports it
loaded or run; see :class:`~wavestack.drivers.plc.jobs.JobLedger`).

A lost reply is harmless: the machine treats a LOAD identical to the loaded (or loading) job, and a
START of the job that is running or ended, as the same request (it never runs a job id twice); the
link resends the same registers after a timeout or a malformed reply, then reads the machine block
to learn the outcome. The machine reads and checks a job file in the background (LOADING, seconds
for a large job): :meth:`JobControl.load_job` waits for LOADED or FAULT up to its timeout plus
:data:`LOAD_ALLOWANCE_S_PER_POINT` per point, reading the machine block between pauses without
holding the link's lock, so the station's heartbeat goes on meanwhile.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

from wavestack.drivers.errors import DeviceError, DeviceTimeout, ProtocolError
from wavestack.drivers.plc.gate import HeartbeatEchoStale, PlcNotReady, command_refusal, no_scan_since, not_ready
from wavestack.drivers.plc.job_file import JobReceipt, job_file_name
from wavestack.drivers.plc.jobs import (JobAction, JobLedger, JobLimits, JobRefused, MachineState, MachineStatus,
                                        decode_machine)
from wavestack.drivers.plc.register_map import RegisterBlock, RegisterMap
from wavestack.drivers.plc.status import PlcStatus
from wavestack.drivers.plc.transport import LinkTiming, ModbusTransport, deadline_after

__all__ = ["LOAD_ALLOWANCE_S_PER_POINT", "JobControl", "JobNotReady", "JobRejected"]

_log = logging.getLogger(__name__)

_POLL_S = 0.02  # between machine-block reads while waiting for a load or start to show
#: Time a load may take per point of the job beyond the call's timeout, s: the simulated machine
#: checked 60,000-150,000 points a second on the shared 2-core machine (300,000 points in 2.0-4.9 s
#: at load 10); this allows 20,000 (25 s more for 500,000 points).
LOAD_ALLOWANCE_S_PER_POINT = 5e-5


class JobNotReady(JobRefused, PlcNotReady):
    """The readiness gate refused a job action (not scanning, tripped, e-stop, busy); nothing was sent."""


class JobRejected(DeviceError):
    """The machine refused a load (state FAULT) or did not take an action; :attr:`status` says why."""

    def __init__(self, device: str, message: str, status: MachineStatus) -> None:
        super().__init__(device, message)
        self.status = status


class JobControl:
    """Job verbs; mixed into :class:`~wavestack.drivers.plc.driver.PolishingLink` (see the module docstring)."""

    # provided by PolishingLink
    _lock: threading.RLock
    _map: RegisterMap
    _device: str
    _monitor: bool
    _self_check_passed: bool
    _echo_stale: bool
    _echo_at_last_command: int | None
    _beat: int
    _heartbeat_pending: bool
    _timing: LinkTiming
    _transport: ModbusTransport
    _jobs: JobLedger
    _job_limits: JobLimits | None

    if TYPE_CHECKING:
        def _send_heartbeat(self, deadline: float) -> None: ...
        def _read_status(self, deadline: float) -> PlcStatus: ...
        def _echo_lag_error(self, status: PlcStatus) -> HeartbeatEchoStale | None: ...
        def _read_block(self, block: RegisterBlock, deadline: float) -> list[int]: ...
        def _write(self, address: int, values: list[int], function_code: int, deadline: float) -> None: ...

    # ----------------------------------------------------------------------------- public verbs
    @property
    def job_limits(self) -> JobLimits | None:
        """The limits every job is checked against before the wire (None: none set, every load refused)."""
        return self._job_limits

    def restrict_jobs(self, limits: JobLimits) -> JobLimits:
        """Set the job limits, or tighten them to the stricter of the old and ``limits`` (never loosened)."""
        with self._lock:
            old = self._job_limits
            if old is not None:
                limits = JobLimits(
                    min(old.max_points, limits.max_points), min(old.max_total_dwell_s, limits.max_total_dwell_s),
                    min(old.max_dwell_per_point_s, limits.max_dwell_per_point_s),
                    min(old.max_feed_mm_s, limits.max_feed_mm_s),
                    (max(old.travel_x_mm[0], limits.travel_x_mm[0]), min(old.travel_x_mm[1], limits.travel_x_mm[1])),
                    (max(old.travel_y_mm[0], limits.travel_y_mm[0]), min(old.travel_y_mm[1], limits.travel_y_mm[1])))
            self._job_limits = limits
            return limits

    def next_job_id(self) -> int:
        """The next job id after this host's own: never one spent (:class:`~wavestack.drivers.plc.jobs.JobLedger`).

        Call :meth:`note_used_job_ids` first with the ids of the job files already in the job folder.
        """
        with self._lock:
            return self._jobs.next_id()

    def note_used_job_ids(self, job_ids: Iterable[int]) -> None:
        """Ids spent by an earlier session (e.g. ``used_job_ids(job_folder)``): never handed out again."""
        with self._lock:
            self._jobs.note_used(job_ids)

    def read_machine(self, timeout_s: float = 2.0) -> MachineStatus:
        """The machine block: state, reason, job id, progress.

        Raises
        ------
        ValueError
            The register map has no machine block.
        ProtocolError
            The block holds an unknown state or reason code.
        PlcRefused
            Exception 4 while the watchdog is tripped.
        """
        deadline = deadline_after(timeout_s)
        with self._lock:
            return self._read_machine(deadline)

    def load_job(self, receipt: JobReceipt, job_id: int, timeout_s: float = 2.0) -> MachineStatus:
        """Announce a written job file (action LOAD) and wait until the machine has checked it.

        Parameters
        ----------
        receipt
            From :func:`~wavestack.drivers.plc.job_file.write_job_file`.
        job_id
            The job's id (:meth:`next_job_id`); must be the receipt's.
        timeout_s
            Budget for the gate, the write and the machine's check; the check may take
            :data:`LOAD_ALLOWANCE_S_PER_POINT` per point more.

        Returns
        -------
        MachineStatus
            LOADED with ``job_id``.

        Raises
        ------
        JobRefused
            Before the wire: the id is not the receipt's or was used, no job limits are set, the job
            breaks them, or (:class:`JobNotReady`) the gate refuses (not scanning, tripped, e-stop,
            busy with a pass, or a job running or loading).
        JobRejected
            The machine refused the file (FAULT; :attr:`JobRejected.status` has the reason code).
        DeviceTimeout
            Also when the machine is still LOADING at the end of the budget.
        ProtocolError, PlcRefused, DeviceDisconnected
            As for a command.
        """
        deadline = deadline_after(timeout_s)
        with self._lock:
            registers = self._load_registers(receipt, job_id)
            machine = self._job_gate(f"load job {job_id}", deadline)
            if machine.state in (MachineState.RUNNING, MachineState.LOADING):
                raise JobNotReady(self._device, f"refusing to load job {job_id}: the machine is busy with job "
                                  f"{machine.job_id} ({machine.describe()})")
            self._jobs.use(job_id)  # spent from here on, whatever the machine answers
            self._write_job(registers, deadline)
        status = self._await_machine(job_id, (MachineState.LOADED, MachineState.FAULT),
                                     deadline + receipt.point_count * LOAD_ALLOWANCE_S_PER_POINT)
        if status.state is MachineState.LOADING and status.job_id == job_id:
            raise DeviceTimeout(self._device, f"job {job_id} still LOADING after {timeout_s:g} s + "
                                f"{receipt.point_count * LOAD_ALLOWANCE_S_PER_POINT:.2f} s for its "
                                f"{receipt.point_count} points; expected LOADED or FAULT")
        if status.state is not MachineState.LOADED:
            with self._lock:
                self._jobs.refused(status)
            raise JobRejected(self._device, f"the machine refused job {job_id}: {status.describe()}", status)
        _log.info("%s: job %d loaded (%d points, CRC-32 %08x)", self._device, job_id, receipt.point_count,
                  receipt.crc32)
        return status

    def start_job(self, job_id: int, timeout_s: float = 2.0) -> MachineStatus:
        """Start the loaded job (action START); returns the machine block once it shows the run.

        A job that is already running or ended under ``job_id`` (a retry after a lost reply) is not
        started again: its status is returned.

        Raises
        ------
        JobRefused
            Before the wire: the machine has not loaded ``job_id``, or (:class:`JobNotReady`) the gate.
        JobRejected
            The machine did not start it.
        """
        deadline = deadline_after(timeout_s)
        with self._lock:
            machine = self._job_gate(f"start job {job_id}", deadline)
            started = (MachineState.RUNNING, MachineState.DONE, MachineState.ABORTED)
            if machine.job_id == job_id and machine.state in started:
                return machine
            if machine.state is not MachineState.LOADED or machine.job_id != job_id:
                raise JobRefused(self._device, f"refusing to start job {job_id}: the machine is "
                                 f"{machine.describe()}; expected LOADED with job {job_id}")
            self._write_job(self._map.encode_job(JobAction.START, job_id, 0, machine.point_count, 0.0), deadline)
        status = self._await_machine(job_id, started, deadline)
        if status.state not in started:
            raise JobRejected(self._device, f"job {job_id} did not start: {status.describe()}", status)
        _log.info("%s: job %d started", self._device, job_id)
        return status

    def abort_job(self, job_id: int, timeout_s: float = 2.0) -> MachineStatus:
        """Stop a loaded or running job (action ABORT): it ends ABORTED (HOST_ABORT), removal so far kept.

        No readiness gate: stopping is the safe direction. Only a monitor link is refused.
        """
        deadline = deadline_after(timeout_s)
        with self._lock:
            if self._monitor:
                raise ProtocolError(self._device, "refusing to abort a job: a monitor link sends nothing")
            self._transport.ensure_connected(deadline)
            self._write_job(self._map.encode_job(JobAction.ABORT, job_id, 0, 0, 0.0), deadline)
            return self._read_machine(deadline)

    # ----------------------------------------------------------------------------- internals
    def _job_blocks(self) -> tuple[RegisterBlock, RegisterBlock]:
        if self._map.job is None or self._map.machine is None:
            raise ValueError(f"{self._device}: the register map has no job and machine blocks "
                             "(configure job_register and machine_register)")
        return self._map.job, self._map.machine

    def _read_machine(self, deadline: float) -> MachineStatus:
        _, block = self._job_blocks()
        registers = self._read_block(block, deadline)
        assert block.word_order is not None
        try:
            status = decode_machine(registers, block.word_order)
        except ValueError as error:
            raise ProtocolError(self._device, f"machine block (registers {block.start}-{block.stop - 1}): "
                                f"{error}") from None
        self._jobs.saw(status)
        return status

    def _load_registers(self, receipt: JobReceipt, job_id: int) -> list[int]:
        """The LOAD registers, after every check that needs no wire (ids, limits)."""
        self._job_blocks()
        name = job_file_name(job_id)
        if receipt.summary.job_id != job_id or receipt.path.name != name:
            raise JobRefused(self._device, f"refusing to load job {job_id}: the receipt is for job "
                             f"{receipt.summary.job_id} ({receipt.path.name}); expected {name}")
        if self._jobs.used(job_id):
            raise JobRefused(self._device, f"refusing to load job {job_id}: the id is spent (announced by this host, "
                             "in the job folder, or loaded or run by the machine); take next_job_id()")
        if self._job_limits is None:
            raise JobRefused(self._device, f"refusing to load job {job_id}: no job limits are set (restrict_jobs)")
        why = self._job_limits.violation(receipt.summary)
        if why is not None:
            raise JobRefused(self._device, f"job {job_id} refused before the wire: {why}")
        return self._map.encode_job(JobAction.LOAD, job_id, receipt.crc32, receipt.point_count, receipt.total_dwell_s)

    def _job_gate(self, what: str, deadline: float) -> MachineStatus:
        """Refuse unless the PLC may take a job action now; the machine block."""
        refusal = command_refusal(self._device, monitor=self._monitor, self_check_passed=self._self_check_passed,
                                  echo_stale=self._echo_stale)
        if refusal is not None:
            raise JobNotReady(self._device, f"refusing to {what}: {refusal.detail}")
        self._transport.ensure_connected(deadline)
        if self._heartbeat_pending:
            self._send_heartbeat(deadline)
        status = self._read_status(deadline)
        stale = self._echo_lag_error(status)
        if stale is not None:
            self._echo_stale = True
            raise JobNotReady(self._device, f"refusing to {what}: {stale.detail}")
        why = no_scan_since(self._echo_at_last_command, self._beat, status) or not_ready(status)
        if why is not None:
            raise JobNotReady(self._device, f"refusing to {what}: the PLC is {why}")
        self._echo_at_last_command = status.heartbeat_echo
        return self._read_machine(deadline)

    def _write_job(self, registers: list[int], deadline: float) -> None:
        """Write the job block, resending the same registers after a timeout or malformed reply."""
        block, _ = self._job_blocks()
        attempts = 0
        while True:
            attempts += 1
            try:
                self._transport.ensure_connected(deadline)
                self._write(block.start, registers, block.write_function or 16, deadline)
                return
            except (DeviceTimeout, ProtocolError) as error:
                if getattr(error, "exception_code", None) is not None:
                    raise  # the PLC answered: an exception reply is final
                if attempts > self._timing.command_retries or time.monotonic() >= deadline:
                    raise
                _log.warning("%s: job write, attempt %d failed (%s); resending", self._device, attempts, error.detail)

    def _await_machine(self, job_id: int, states: tuple[MachineState, ...], deadline: float) -> MachineStatus:
        """Read the machine block until it shows ``job_id`` in one of ``states``, or the deadline.

        The link's lock is taken per read only: the heartbeat goes on between them.
        """
        while True:
            with self._lock:
                status = self._read_machine(max(deadline, time.monotonic() + self._timing.io_timeout_s))
            if status.job_id == job_id and status.state in states:
                return status
            if time.monotonic() + _POLL_S >= deadline:
                return status
            time.sleep(_POLL_S)
