"""Polishing jobs seen from the host: machine state, reason codes, job limits and the job-id ledger (pure).

A polishing program goes to the machine as a job file (:mod:`.job_file`); over Modbus the host
announces it in the job block (action LOAD: job id, CRC-32, point count, total dwell) and starts it
(action START); the machine reports its state in the machine block:

- ``state`` (:class:`MachineState`): IDLE, LOADED, RUNNING, DONE, ABORTED, FAULT, LOADING;
- ``reason`` (:class:`JobReason`): why a load was refused (FAULT) or a run ended early (ABORTED);
- ``job id``, ``points done`` and ``point count`` of the job the state belongs to.

Nothing here does I/O: the link (:mod:`.job_control`) reads and writes, these values decide.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from wavestack.drivers.errors import LimitError
from wavestack.drivers.plc.codec import WordOrder, decode_uint32

__all__ = ["JOB_BLOCK_COUNT", "MACHINE_BLOCK_COUNT", "MAX_JOB_ID", "SPENT_STATES", "JobAction", "JobLedger",
           "JobLimits", "JobReason", "JobRefused", "JobSummary", "MachineState", "MachineStatus", "decode_machine"]

#: Registers of the job block: action, job id, CRC-32 (2), point count (2), total dwell float32 (2).
JOB_BLOCK_COUNT = 8
#: Registers of the machine block: state, reason, job id, points done (2), point count (2).
MACHINE_BLOCK_COUNT = 7
#: Job ids travel as a uint16; 0 means "no job".
MAX_JOB_ID = 0xFFFF


class JobRefused(LimitError):
    """A job the host may not announce or start (limits, the readiness gate, a used id); nothing was sent."""


class JobAction(enum.IntEnum):
    """The job block's first register: what the write asks of the machine."""

    LOAD = 1  #: read the job file ``job-NNNNN.wsjob`` (LOADING), check it against the announced values and limits
    START = 2  #: run the loaded job (its id must be the one loaded)
    ABORT = 3  #: stop the running job (ends ABORTED, reason HOST_ABORT, removal so far kept)


class MachineState(enum.IntEnum):
    """The machine block's state register."""

    IDLE = 0  #: no job loaded
    LOADED = 1  #: a job passed its checks and waits for START
    RUNNING = 2  #: the job is being polished, point by point
    DONE = 3  #: every point was polished
    ABORTED = 4  #: the run stopped early (reason says why); the part polished so far stays polished
    FAULT = 5  #: the last LOAD was refused (reason says why); the next LOAD may clear it
    LOADING = 6  #: the machine reads and checks the announced job file (seconds for a large job)


class JobReason(enum.IntEnum):
    """The machine block's reason register: why a load was refused or a run ended early."""

    NONE = 0  #: nothing to report
    FILE_MISSING = 1  #: no job file by that name in the job folder
    FILE_TRUNCATED = 2  #: the file ends before its CRC trailer, or is shorter than the trailer says
    FILE_CORRUPT = 3  #: the body does not match the file's own CRC-32, or is not a job document
    CRC_MISMATCH = 4  #: the file is intact but its CRC-32 differs from the announced one
    ID_MISMATCH = 5  #: the file's job id differs from the announced one
    COUNT_MISMATCH = 6  #: the file's point count differs from the announced one
    DWELL_MISMATCH = 7  #: the file's total dwell differs from the announced one
    TOO_MANY_POINTS = 8  #: more points than the machine takes
    TOTAL_DWELL_LIMIT = 9  #: total dwell above the machine's limit
    DWELL_LIMIT = 10  #: a point's dwell negative, non-finite or above the per-point limit
    FEED_LIMIT = 11  #: a feed rate non-positive, non-finite or above the machine's limit
    TRAVEL_LIMIT = 12  #: a point outside the machine's travel
    JOB_ID_USED = 13  #: that job id was loaded or run before (ids are never reused)
    UNSUPPORTED_FORMAT = 14  #: a job-file format or version the machine does not read
    ESTOP = 15  #: the emergency stop stopped the run
    WATCHDOG = 16  #: the heartbeat watchdog tripped during the run
    PLC_RESTART = 17  #: the PLC restarted during the run
    HOST_ABORT = 18  #: the host asked for an abort
    MACHINE_FAULT = 19  #: the machine itself failed during the run (its log says how)
    NOT_SIGNED = 20  #: the machine has a job key and the file's HMAC is missing or wrong

    @property
    def meaning(self) -> str:
        """One line for messages and the README."""
        return _MEANINGS[self]


_MEANINGS = {
    JobReason.NONE: "no reason recorded",
    JobReason.FILE_MISSING: "no job file by that name in the job folder",
    JobReason.FILE_TRUNCATED: "the job file is truncated (no CRC trailer, or shorter than it says)",
    JobReason.FILE_CORRUPT: "the job file is corrupt (its own CRC-32 does not match, or it is not a job)",
    JobReason.CRC_MISMATCH: "the job file's CRC-32 differs from the announced one",
    JobReason.ID_MISMATCH: "the job file's id differs from the announced one",
    JobReason.COUNT_MISMATCH: "the job file's point count differs from the announced one",
    JobReason.DWELL_MISMATCH: "the job file's total dwell differs from the announced one",
    JobReason.TOO_MANY_POINTS: "more points than the machine takes",
    JobReason.TOTAL_DWELL_LIMIT: "total dwell above the machine's limit",
    JobReason.DWELL_LIMIT: "a dwell outside 0 .. the per-point limit",
    JobReason.FEED_LIMIT: "a feed rate outside (0, the machine's limit]",
    JobReason.TRAVEL_LIMIT: "a point outside the machine's travel",
    JobReason.JOB_ID_USED: "the job id was used before",
    JobReason.UNSUPPORTED_FORMAT: "a job-file format or version the machine does not read",
    JobReason.ESTOP: "emergency stop during the run",
    JobReason.WATCHDOG: "heartbeat watchdog trip during the run",
    JobReason.PLC_RESTART: "PLC restart during the run",
    JobReason.HOST_ABORT: "aborted by the host",
    JobReason.MACHINE_FAULT: "the machine failed during the run (see its log)",
    JobReason.NOT_SIGNED: "the job file carries no valid HMAC for the machine's job key",
}


@dataclass(frozen=True)
class MachineStatus:
    """The machine block as read.

    Attributes
    ----------
    state
        Where the machine's job life is.
    reason
        Why a load was refused or a run ended early (NONE otherwise).
    job_id
        The job the state belongs to (0: none yet).
    points_done
        Points completed (the current one not counted until its dwell ends).
    point_count
        Points of that job.
    """

    state: MachineState
    reason: JobReason
    job_id: int
    points_done: int
    point_count: int

    def describe(self) -> str:
        """``"ABORTED (job 7, 120/400 points): emergency stop during the run"``."""
        text = f"{self.state.name} (job {self.job_id}, {self.points_done}/{self.point_count} points)"
        return text if self.reason is JobReason.NONE else f"{text}: {self.reason.meaning}"


def decode_machine(registers: Sequence[int], order: WordOrder) -> MachineStatus:
    """Decode the machine block.

    Parameters
    ----------
    registers
        :data:`MACHINE_BLOCK_COUNT` registers: state, reason, job id, points done (uint32), point count (uint32).
    order
        Byte order of the two uint32 values.

    Raises
    ------
    ValueError
        A wrong register count, an unknown state or reason code.

    Examples
    --------
    >>> decode_machine([2, 0, 7, 0, 12, 0, 40], "ABCD")
    MachineStatus(state=<MachineState.RUNNING: 2>, reason=<JobReason.NONE: 0>, job_id=7, points_done=12, point_count=40)
    """
    if len(registers) != MACHINE_BLOCK_COUNT:
        raise ValueError(f"the machine block has {MACHINE_BLOCK_COUNT} registers, got {len(registers)}")
    try:
        state = MachineState(int(registers[0]))
    except ValueError:
        raise ValueError(f"unknown machine state {registers[0]}; expected 0..{len(MachineState) - 1}") from None
    try:
        reason = JobReason(int(registers[1]))
    except ValueError:
        raise ValueError(f"unknown job reason code {registers[1]}; expected 0..{len(JobReason) - 1}") from None
    return MachineStatus(state=state, reason=reason, job_id=int(registers[2]),
                         points_done=decode_uint32(registers[3:5], order),
                         point_count=decode_uint32(registers[5:7], order))


@dataclass(frozen=True)
class JobSummary:
    """What the limits look at in a job: counts and extremes (computed by the writer from the points).

    Attributes
    ----------
    job_id, point_count, total_dwell_s
        As announced.
    max_dwell_s, min_dwell_s
        Extremes of the per-point dwell, s.
    max_feed_mm_s, min_feed_mm_s
        Extremes of the feed rates, mm/s.
    x_range_mm, y_range_mm
        ``(lowest, highest)`` position in the machine frame, mm.
    """

    job_id: int
    point_count: int
    total_dwell_s: float
    max_dwell_s: float
    min_dwell_s: float
    max_feed_mm_s: float
    min_feed_mm_s: float
    x_range_mm: tuple[float, float]
    y_range_mm: tuple[float, float]


@dataclass(frozen=True)
class JobLimits:
    """Limits every job must meet before the host announces it (the machine checks its own again).

    Attributes
    ----------
    max_points
        Most points in one job.
    max_total_dwell_s
        Longest total dwell, s.
    max_dwell_per_point_s
        Longest dwell at one point, s.
    max_feed_mm_s
        Fastest feed between points, mm/s.
    travel_x_mm, travel_y_mm
        ``(lo, hi)`` reachable positions in the machine frame, mm.

    Examples
    --------
    >>> limits = JobLimits(100, 60.0, 2.0, 50.0, (-20.0, 20.0), (-20.0, 20.0))
    >>> summary = JobSummary(1, 10, 12.0, 3.0, 0.5, 10.0, 5.0, (-5.0, 5.0), (-5.0, 5.0))
    >>> limits.violation(summary)
    'a dwell of 3 s exceeds max_dwell_per_point_s = 2 s'
    """

    max_points: int
    max_total_dwell_s: float
    max_dwell_per_point_s: float
    max_feed_mm_s: float
    travel_x_mm: tuple[float, float]
    travel_y_mm: tuple[float, float]

    def __post_init__(self) -> None:
        if not (isinstance(self.max_points, int) and 1 <= self.max_points <= 0xFFFFFFFF):
            raise ValueError(f"max_points must be an integer 1..2**32-1, got {self.max_points!r}")
        for name in ("max_total_dwell_s", "max_dwell_per_point_s", "max_feed_mm_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        for name in ("travel_x_mm", "travel_y_mm"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"{name} must be (lo, hi) with finite lo < hi, got {(lo, hi)!r}")

    def violation(self, job: JobSummary) -> str | None:
        """The first limit ``job`` breaks, as a message naming the value and the limit, or None."""
        checks = (
            (1 <= job.point_count <= self.max_points, f"{job.point_count} points; expected 1..{self.max_points}"),
            (0 < job.total_dwell_s <= self.max_total_dwell_s,
             f"a total dwell of {job.total_dwell_s:g} s; expected > 0 and <= max_total_dwell_s = "
             f"{self.max_total_dwell_s:g} s"),
            (job.min_dwell_s >= 0, f"a negative dwell ({job.min_dwell_s:g} s)"),
            (job.max_dwell_s <= self.max_dwell_per_point_s,
             f"a dwell of {job.max_dwell_s:g} s exceeds max_dwell_per_point_s = {self.max_dwell_per_point_s:g} s"),
            (job.min_feed_mm_s > 0, f"a feed rate of {job.min_feed_mm_s:g} mm/s; expected > 0"),
            (job.max_feed_mm_s <= self.max_feed_mm_s,
             f"a feed rate of {job.max_feed_mm_s:g} mm/s exceeds max_feed_mm_s = {self.max_feed_mm_s:g} mm/s"),
            (_inside(job.x_range_mm, self.travel_x_mm),
             f"x from {job.x_range_mm[0]:g} to {job.x_range_mm[1]:g} mm leaves the travel {self.travel_x_mm} mm"),
            (_inside(job.y_range_mm, self.travel_y_mm),
             f"y from {job.y_range_mm[0]:g} to {job.y_range_mm[1]:g} mm leaves the travel {self.travel_y_mm} mm"),
        )
        for ok, why in checks:
            if not ok:  # NaN compares False: a non-finite value is a violation too
                return why
        return None


def _inside(span: tuple[float, float], travel: tuple[float, float]) -> bool:
    return travel[0] <= span[0] and span[1] <= travel[1]


#: States in which the machine block's job id was loaded (or run) by the machine: that id is spent.
SPENT_STATES = frozenset({MachineState.LOADED, MachineState.RUNNING, MachineState.DONE, MachineState.ABORTED})


class JobLedger:
    """The job ids the host has spent; a new job gets the next id after the host's own, never a spent one.

    An id is spent when this host announced it (its job file exists), when a job file in the job
    folder has it, or when the machine reports it loaded or run (LOADED, RUNNING, DONE, ABORTED), or
    refuses it as used before (JOB_ID_USED, the machine's own log). An id the machine reports in
    any other state (a load it refused, FAULT) is not spent by that report, and no report moves the
    host's next id: only ids this host announced do. So no peer can make the host skip ahead, and a
    refused load costs nothing but its own id.

    Ids are 1..65535 and never wrap: at one job per ten minutes the range lasts over a year; a
    station that reaches it is told so (a new machine log, or a new job folder, starts afresh).

    Examples
    --------
    >>> ledger = JobLedger()
    >>> ledger.saw(MachineStatus(MachineState.FAULT, JobReason.FILE_MISSING, 65535, 0, 0))  # refused: not spent
    >>> ledger.saw(MachineStatus(MachineState.DONE, JobReason.NONE, 2, 10, 10))             # run: spent
    >>> ledger.next_id()
    1
    >>> ledger.use(1); ledger.next_id()   # 2 was run by the machine: skipped
    3
    """

    def __init__(self) -> None:
        self._used: set[int] = set()
        self._own_highest = 0

    @property
    def highest(self) -> int:
        """The highest id this host announced or found in its job folder (0: none)."""
        return self._own_highest

    def used(self, job_id: int) -> bool:
        """Whether ``job_id`` is spent (see the class notes)."""
        return job_id in self._used

    def saw(self, status: MachineStatus) -> None:
        """The machine block as read: its job id is spent when the machine loaded or ran it."""
        if status.state in SPENT_STATES and status.job_id > 0:
            self._used.add(int(status.job_id))

    def refused(self, status: MachineStatus) -> None:
        """A load refused: the id is spent when the machine's log has it (JOB_ID_USED)."""
        if status.reason is JobReason.JOB_ID_USED and status.job_id > 0:
            self._used.add(int(status.job_id))

    def note_used(self, job_ids: Iterable[int]) -> None:
        """Ids of the job files already in the job folder (this host's earlier sessions)."""
        for job_id in job_ids:
            self.use(job_id)

    def use(self, job_id: int) -> None:
        """``job_id`` is being announced by this host: spent, whatever the machine answers."""
        self._used.add(int(job_id))
        self._own_highest = max(self._own_highest, int(job_id))

    def next_id(self) -> int:
        """The next id: the first after this host's highest that is not spent.

        Raises
        ------
        JobRefused
            No id up to 65535 is left.
        """
        candidate = self._own_highest + 1
        while candidate in self._used:
            candidate += 1
        if candidate > MAX_JOB_ID:
            raise JobRefused("job ledger", f"every job id up to {MAX_JOB_ID} is spent; start a new machine log "
                             "and job folder")
        return candidate
