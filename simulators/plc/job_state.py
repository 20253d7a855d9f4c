"""A polishing job's life in the simulated machine, as data: states, reason codes, a transition table.

Re-implemented from the README's register map (not imported from the driver): the machine block's
state register holds a :class:`JobState`, its reason register a :class:`StopReason`.

============  ==========================================================================
event         effect
============  ==========================================================================
LOAD          IDLE, LOADED, DONE, ABORTED, FAULT -> LOADING (the file is read and checked
              in the background; a loaded job replaced is spent)
LOAD_OK       LOADING -> LOADED
LOAD_REFUSED  LOADING -> FAULT (with the reason)
START         LOADED -> RUNNING
FINISH        RUNNING -> DONE
STOP          RUNNING, LOADED, LOADING -> ABORTED (e-stop, watchdog, restart, host abort)
============  ==========================================================================

Anything else is not a transition (:func:`next_state` returns None): a load while running or
loading, a start of anything but a loaded job, a finish or stop of a job that is not running. The
machine answers those requests with a Modbus exception and keeps its state.
"""

from __future__ import annotations

import enum

__all__ = ["JobEvent", "JobState", "StopReason", "next_state"]


class JobState(enum.IntEnum):
    """The machine block's state register."""

    IDLE = 0
    LOADED = 1
    RUNNING = 2
    DONE = 3
    ABORTED = 4
    FAULT = 5
    LOADING = 6


class StopReason(enum.IntEnum):
    """The machine block's reason register (numbers as in the README's table)."""

    NONE = 0
    FILE_MISSING = 1
    FILE_TRUNCATED = 2
    FILE_CORRUPT = 3
    CRC_MISMATCH = 4
    ID_MISMATCH = 5
    COUNT_MISMATCH = 6
    DWELL_MISMATCH = 7
    TOO_MANY_POINTS = 8
    TOTAL_DWELL_LIMIT = 9
    DWELL_LIMIT = 10
    FEED_LIMIT = 11
    TRAVEL_LIMIT = 12
    JOB_ID_USED = 13
    UNSUPPORTED_FORMAT = 14
    ESTOP = 15
    WATCHDOG = 16
    PLC_RESTART = 17
    HOST_ABORT = 18
    MACHINE_FAULT = 19
    NOT_SIGNED = 20


class JobEvent(enum.Enum):
    """What happens to a job."""

    LOAD = "load announced"
    LOAD_OK = "load accepted"
    LOAD_REFUSED = "load refused"
    START = "start"
    FINISH = "finish"
    STOP = "stop"


_NOT_RUNNING = (JobState.IDLE, JobState.LOADED, JobState.DONE, JobState.ABORTED, JobState.FAULT)
_TABLE: dict[tuple[JobState, JobEvent], JobState] = {
    **{(state, JobEvent.LOAD): JobState.LOADING for state in _NOT_RUNNING},
    (JobState.LOADING, JobEvent.LOAD_OK): JobState.LOADED,
    (JobState.LOADING, JobEvent.LOAD_REFUSED): JobState.FAULT,
    (JobState.LOADED, JobEvent.START): JobState.RUNNING,
    (JobState.RUNNING, JobEvent.FINISH): JobState.DONE,
    (JobState.RUNNING, JobEvent.STOP): JobState.ABORTED,
    (JobState.LOADED, JobEvent.STOP): JobState.ABORTED,
    (JobState.LOADING, JobEvent.STOP): JobState.ABORTED,
}


def next_state(state: JobState, event: JobEvent) -> JobState | None:
    """The state after ``event`` in ``state``, or None when the event is not allowed there (pure).

    Examples
    --------
    >>> next_state(JobState.LOADED, JobEvent.START)
    <JobState.RUNNING: 2>
    >>> next_state(JobState.RUNNING, JobEvent.LOAD) is None   # busy: a running job is never replaced
    True
    """
    return _TABLE.get((state, event))
