"""Hand a job to the machine and wait for its end: the loop's only I/O with the polishing machine.

:func:`write_job` writes the job file atomically into the job folder; :func:`announce_and_start`
announces it over Modbus (id, CRC-32, point count, total dwell; the link refuses before the wire
what its limits, the gate or an id already used forbid) and starts it. :func:`wait_for_done` then polls the machine's state
every ``poll_s`` until the job ends, the timeout passes or the operator stops the loop; the
station's own thread keeps the heartbeat going meanwhile, and the heartbeat it last saw is watched
too. What ended the wait is one :class:`MachineEnd` value:

- ``DONE`` of this job: the only good end;
- ``ABORTED`` or ``FAULT`` (an e-stop, a watchdog trip, a job the machine refused: its reason code);
- the machine idle or holding another job once the start had time to show (a PLC restart lost
  it): never started again, the loop faults;
- the watchdog tripped (the station's heartbeat says so), or the PLC refuses read after read with
  exception 4 (tripped or e-stopped, also when the station's heartbeat has stopped): the state is
  read a few more times for the points done, then the wait ends;
- no answer before ``timeout_s`` (a PLC that stays away), or a stop by the operator: the host then
  stops its heartbeat with the station, and the PLC's watchdog stops the machine.

A read that fails (a lost connection, a PLC restarting) is not an end by itself: the link
reconnects on the next call, and the wait goes on until its deadline.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from wavestack.drivers.errors import DeviceError
from wavestack.drivers.plc import JobFile, JobReceipt, PolishingLink, write_job_file
from wavestack.station import Heartbeat

logger = logging.getLogger(__name__)

__all__ = ["MachineEnd", "announce_and_start", "state_name", "wait_for_done", "write_job"]

_DEVICE_FAILURE = 4  # the Modbus exception a tripped (or e-stopped) PLC answers


@dataclass(frozen=True)
class MachineEnd:
    """How a job's wait ended.

    Attributes
    ----------
    state : str
        The machine state's name for this job (``DONE``, ``ABORTED``, ``FAULT``), ``LOST`` when the
        machine shows another job or none (``reason`` then holds the state it shows), or ``UNKNOWN``.
    reason : str
        The machine's reason code name (empty when none), or why the wait ended without it.
    points_done, point_count : int
        Progress last read (-1 when never read).
    detail : str
        One line for the operator and the record.
    done_ns : int
        ``time.time_ns()`` when the end was seen.
    """

    state: str
    reason: str
    points_done: int
    point_count: int
    detail: str
    done_ns: int

    @property
    def done(self) -> bool:
        """True only for the machine's done of this job."""
        return self.state == "DONE"


def write_job(folder: Path, job: JobFile, key: bytes | None = None) -> JobReceipt:
    """Write ``job`` atomically into the job folder (with its HMAC under ``key``, when given); returns its
    receipt (path, CRC-32, points, dwell).

    Raises
    ------
    OSError
        The job folder cannot be written.
    """
    receipt = write_job_file(folder, job, key=key)
    logger.info("job %d written: %s (CRC-32 %08x, %d points, %.1f s)", job.job_id, receipt.path, receipt.crc32,
                receipt.point_count, receipt.total_dwell_s)
    return receipt


def announce_and_start(link: PolishingLink, receipt: JobReceipt, job_id: int, *, timeout_s: float) -> None:
    """Announce the written job over Modbus and start it.

    Raises
    ------
    JobRefused
        The link's limits or gate refused it before the wire.
    JobRejected
        The machine refused it (its state and reason code on the error's ``status``).
    DeviceError
        The PLC did not take it.
    """
    link.load_job(receipt, job_id, timeout_s=timeout_s)
    link.start_job(job_id, timeout_s=timeout_s)


def state_name(value: object) -> str:
    """An enum member's name (a state or reason code), or the text of anything else."""
    return str(getattr(value, "name", value) or "")


def wait_for_done(link: PolishingLink, job_id: int, *, timeout_s: float, poll_s: float, io_timeout_s: float,
                  stop: threading.Event, heartbeat: Callable[[], Heartbeat | None],
                  start_grace_s: float = 2.0, refused_wait_s: float = 2.0) -> MachineEnd:
    """Poll the machine until job ``job_id`` ends (module notes); never raises a device error.

    ``refused_wait_s``: how long a trip or refused reads persist before the wait ends (the PLC's
    last word on the job is read meanwhile, and the station's heartbeat tells a trip from an e-stop).
    """
    started = time.monotonic()
    deadline = started + timeout_s
    points_done = point_count = -1
    last_error: str | None = None

    def end(state: str, reason: str, detail: str) -> MachineEnd:
        return MachineEnd(state, reason, points_done, point_count, detail, time.time_ns())

    refused_since: float | None = None  # when the PLC first refused a read (or the heartbeat saw the trip)
    tripped = False
    while True:
        beat = heartbeat()
        tripped = tripped or bool(beat is not None and beat.watchdog_tripped)
        refused = tripped
        try:
            status = link.read_machine(io_timeout_s)
        except DeviceError as error:
            last_error = str(error)
            refused = refused or getattr(error, "exception_code", None) == _DEVICE_FAILURE
            logger.warning("job %d: machine state not read (%s); retrying", job_id, error)
        else:
            state, reason = state_name(status.state), state_name(status.reason)
            ours = status.job_id == job_id
            if ours:
                points_done, point_count = int(status.points_done), int(status.point_count)
            if ours and state == "DONE":
                return end(state, reason, f"job {job_id} done: {points_done}/{point_count} points")
            if ours and state in ("ABORTED", "FAULT"):
                return end(state, reason, f"job {job_id} {state.lower()} ({reason or 'no reason given'}) after "
                                          f"{points_done}/{point_count} points")
            if not (ours and state in ("LOADED", "RUNNING")) and time.monotonic() - started > start_grace_s:
                return end("LOST", state, f"the machine is {state} with job {status.job_id}, not running job "
                                          f"{job_id} (lost by a PLC restart?); it is not sent again")
        if refused and refused_since is None:
            refused_since = time.monotonic()
        if refused_since is not None and time.monotonic() - refused_since >= refused_wait_s:
            if tripped:
                return end("UNKNOWN", "WATCHDOG", f"the PLC watchdog tripped during job {job_id} "
                                                  f"({points_done}/{point_count} points done when last read)")
            return end("UNKNOWN", "PLC_REFUSED", f"the PLC refuses machine reads during job {job_id} (exception 4: "
                                                 f"watchdog tripped or e-stop; {points_done}/{point_count} points "
                                                 "done when last read)")
        if time.monotonic() >= deadline:
            why = f"; last error: {last_error}" if last_error else ""
            return end("UNKNOWN", "TIMEOUT", f"job {job_id} not done within done_timeout_s = {timeout_s:g} s{why}")
        if stop.wait(poll_s):
            return end("UNKNOWN", "STOPPED", f"stopped while the machine ran job {job_id} "
                                             f"({points_done}/{point_count} points); the PLC watchdog stops it "
                                             "once the heartbeat ends")
