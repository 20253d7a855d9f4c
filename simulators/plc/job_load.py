"""How the simulated machine reads and checks an announced job, off the thread that serves the PLC.

:func:`read_announced_job` reads with the machine's own reader (:mod:`.job_file`: regular files
only, never waiting on a FIFO). A file above :data:`IN_THREAD_BYTES` is parsed in a forked child
(as the machine's controller would parse it in a task of its own): the JSON parser holds the
interpreter lock for the whole parse (1.7 s for 300,000 points on the loaded 2-core machine),
which would starve the PLC's serving thread as surely as parsing on it. The child only parses (no
lock another thread could hold) and must answer within :data:`CHILD_TIMEOUT_S`. Where there is no
``fork`` the file is parsed on the calling thread.
:func:`check_job` is the machine's own judgement of a job it read (pure): the file's CRC-32
against the announced one, the job id, point count and total dwell against the announced values,
then its own limits (points, total dwell, per-point dwell, feed, travel).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.plc.job_file import JobFileRefused, MachineJob, read_job_file
from wavestack.simulators.plc.job_state import StopReason

__all__ = ["CHILD_TIMEOUT_S", "IN_THREAD_BYTES", "MachineLimits", "check_job", "read_announced_job"]


class MachineLimits(Protocol):
    """The machine's own limits a job is checked against (``MachineSimSettings`` has them)."""

    max_points: int
    max_total_dwell_s: float
    max_dwell_per_point_s: float
    max_feed_mm_s: float
    travel_x_mm: tuple[float, float]
    travel_y_mm: tuple[float, float]


#: Largest job file parsed on the calling (loader) thread itself: about 25,000 points, < 0.1 s.
IN_THREAD_BYTES = 1 << 20
#: Longest a child may take to parse a job (the machine's own limit, 500,000 points, takes seconds).
CHILD_TIMEOUT_S = 120.0


def read_announced_job(path: Path, max_bytes: int, key: bytes | None = None) -> MachineJob:
    """Read ``path`` with the machine's reader, in a child process when it is large (module notes).

    Raises
    ------
    JobFileRefused
        As :func:`~wavestack.simulators.plc.job_file.read_job_file`.
    """
    try:
        size = path.stat().st_size
    except OSError:
        size = 0  # the reader says what is wrong with it
    try:
        context = multiprocessing.get_context("fork")
    except ValueError:
        context = None
    if size <= IN_THREAD_BYTES or context is None:
        return read_job_file(path, max_bytes, key)
    receiver, sender = context.Pipe(duplex=False)
    child = context.Process(target=_parse_in_child, args=(path, max_bytes, key, sender), daemon=True)
    child.start()
    sender.close()
    try:
        if not receiver.poll(CHILD_TIMEOUT_S):
            raise JobFileRefused(StopReason.FILE_CORRUPT, f"{path.name}: not read within {CHILD_TIMEOUT_S:g} s")
        try:
            outcome = receiver.recv()
        except EOFError:
            raise JobFileRefused(StopReason.FILE_CORRUPT, f"{path.name}: the reader died reading it") from None
    finally:
        receiver.close()
        if child.is_alive():
            child.kill()
        child.join()
        child.close()
    if isinstance(outcome, JobFileRefused):
        raise outcome
    return outcome


def _parse_in_child(path: Path, max_bytes: int, key: bytes | None,
                    sender: multiprocessing.connection.Connection) -> None:
    try:
        outcome: MachineJob | JobFileRefused = read_job_file(path, max_bytes, key)
    except JobFileRefused as refusal:
        outcome = refusal
    try:
        sender.send(outcome)
    finally:
        sender.close()


def check_job(job: MachineJob, announced: tuple[int, int, int, float], settings: MachineLimits) -> None:
    """Refuse ``job`` unless it is what was announced (id, CRC-32, count, total dwell) and within the limits.

    Raises
    ------
    JobFileRefused
        With the first reason that applies, in the order above.
    """
    job_id, crc32, count, total = announced
    s = settings
    dwell, feed = job.dwell_s, job.feed_mm_s
    file_total = float(np.sum(dwell))
    checks = (
        (job.crc32 == crc32, StopReason.CRC_MISMATCH, f"file CRC-32 {job.crc32:08x}, announced {crc32:08x}"),
        (job.job_id == job_id, StopReason.ID_MISMATCH, f"file job id {job.job_id}, announced {job_id}"),
        (job.point_count == count, StopReason.COUNT_MISMATCH, f"{job.point_count} points, announced {count}"),
        (_close(file_total, job.total_dwell_s) and _close(file_total, total), StopReason.DWELL_MISMATCH,
         f"dwell sums to {file_total:g} s, header {job.total_dwell_s:g} s, announced {total:g} s"),
        (count <= s.max_points, StopReason.TOO_MANY_POINTS, f"{count} points > {s.max_points}"),
        (file_total <= s.max_total_dwell_s, StopReason.TOTAL_DWELL_LIMIT,
         f"total dwell {file_total:g} s > {s.max_total_dwell_s:g} s"),
        (bool(np.all((dwell >= 0) & (dwell <= s.max_dwell_per_point_s))), StopReason.DWELL_LIMIT,
         f"dwell outside [0, {s.max_dwell_per_point_s:g}] s"),
        (bool(np.all((feed > 0) & (feed <= s.max_feed_mm_s))), StopReason.FEED_LIMIT,
         f"feed outside (0, {s.max_feed_mm_s:g}] mm/s"),
        (_within(job.x_mm, s.travel_x_mm) and _within(job.y_mm, s.travel_y_mm), StopReason.TRAVEL_LIMIT,
         f"a point outside the travel x {s.travel_x_mm}, y {s.travel_y_mm} mm"),
    )
    for ok, reason, message in checks:
        if not ok:
            raise JobFileRefused(reason, f"job {job_id}: {message}")


def _close(a: float, b: float) -> bool:
    """Equal to float32 precision of an announced value (relative 1e-6, absolute 1e-6 s)."""
    return abs(a - b) <= 1e-6 * max(1.0, abs(a), abs(b))


def _within(values: NDArray[np.float64], span: tuple[float, float]) -> bool:
    return bool(np.all((values >= span[0]) & (values <= span[1])))
