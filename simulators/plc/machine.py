"""The simulated polishing machine behind the PLC: loads job files, checks them, polishes point by point.

The PLC program hands it the job block's actions (:mod:`.program`); the machine:

- on LOAD reads ``job-NNNNN.wsjob`` from its job folder with its own reader (:mod:`.job_file`),
  and checks the file's CRC-32 against the announced one, the job id, point count and total dwell
  against the announced values, then its own limits (points, total dwell, per-point dwell, feed,
  travel); any failure puts it in FAULT with the reason code. A job id it loaded before is refused
  (JOB_ID_USED): it never runs an id twice. A LOAD identical to the loaded job is a retry: no-op.
- on START runs the job in a thread, in simulated time (``time_scale`` simulated seconds per real
  second): for each point the travel at the file's feed, then the dwell, in slices, so an e-stop,
  a watchdog trip, a PLC restart or the host's abort stops it within one slice. Removal is
  deposited with the machine's own tool (:class:`~.machine_tif.GaussianTool`, which may differ
  from the host's model: width and rate errors, a per-point efficiency spread, noise) and applied to
  the :class:`RemovalTarget` chunk by chunk (every ``flush_s`` real seconds), together with the
  points-done counter, so an abort leaves the part polished exactly as far as the counter says (the
  slice under way when it stops is not polished).

Noise model (where the literature gives no single form): each chunk adds white noise of standard
deviation ``noise_nm * sqrt(chunk dwell / job dwell)`` on the pixels the chunk touched, so a pixel
the whole job touches ends with ``noise_nm`` RMS of process noise.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.plc.job_file import JobFileRefused, MachineJob, read_job_file
from wavestack.simulators.plc.job_state import JobEvent, JobState, StopReason, next_state
from wavestack.simulators.plc.machine_tif import GaussianTool

__all__ = ["MachineSimSettings", "MachineSnapshot", "PolishingMachine", "RemovalTarget"]

_log = logging.getLogger(__name__)

_SLICE_REAL_S = 0.01  # longest real time between two interlock checks within a dwell
_BYTES_PER_POINT = 120  # a generous bound on one point's line in the job file


class RemovalTarget(Protocol):
    """What the machine polishes: a height map it removes from (the simulated optic's surface fits)."""

    @property
    def shape(self) -> tuple[int, int]: ...

    @property
    def pixel_mm(self) -> float: ...

    def apply_removal(self, removal_nm: NDArray[np.float64]) -> None: ...


@dataclass(frozen=True)
class MachineSimSettings:
    """The simulated machine: job folder, speed, its own tool and its own limits.

    Attributes
    ----------
    job_folder
        Where the host writes job files.
    time_scale
        Simulated seconds per real second (> 0; e.g. 100 runs a 100 s job in 1 s).
    tif_fwhm_mm, tif_peak_rate_nm_s
        The nominal tool (the host's model, ideally).
    width_error, rate_error
        The real tool's FWHM and peak rate differ from nominal by these fractions (> -1).
    efficiency_spread
        Per-point efficiency ``1 + efficiency_spread * u``, ``u`` uniform on [-1, 1] (in [0, 1)).
    noise_nm
        Process noise a whole job leaves on a pixel, nm RMS (>= 0).
    seed
        Seed of the machine's random draws (per job: seed and job id).
    max_points, max_total_dwell_s, max_dwell_per_point_s, max_feed_mm_s, travel_x_mm, travel_y_mm
        The machine's own limits.
    flush_s
        Real time between two chunks applied to the target (> 0).
    """

    job_folder: Path
    time_scale: float = 100.0
    tif_fwhm_mm: float = 3.0
    tif_peak_rate_nm_s: float = 10.0
    width_error: float = 0.0
    rate_error: float = 0.0
    efficiency_spread: float = 0.0
    noise_nm: float = 0.0
    seed: int = 0
    max_points: int = 500_000
    max_total_dwell_s: float = 36_000.0
    max_dwell_per_point_s: float = 60.0
    max_feed_mm_s: float = 100.0
    travel_x_mm: tuple[float, float] = (-100.0, 100.0)
    travel_y_mm: tuple[float, float] = (-100.0, 100.0)
    flush_s: float = 0.05

    def __post_init__(self) -> None:
        object.__setattr__(self, "job_folder", Path(self.job_folder))
        positive = ("time_scale", "tif_fwhm_mm", "max_total_dwell_s", "max_dwell_per_point_s", "max_feed_mm_s",
                    "flush_s")
        for name in positive:
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"MachineSimSettings: {name} must be finite and > 0, got {getattr(self, name)!r}")
        checks = (("tif_peak_rate_nm_s", self.tif_peak_rate_nm_s >= 0), ("noise_nm", self.noise_nm >= 0),
                  ("width_error", self.width_error > -1), ("rate_error", self.rate_error >= -1),
                  ("efficiency_spread", 0 <= self.efficiency_spread < 1),
                  ("max_points", isinstance(self.max_points, int) and self.max_points >= 1),
                  ("seed", isinstance(self.seed, int) and self.seed >= 0))
        for name, ok in checks:
            if not ok:
                raise ValueError(f"MachineSimSettings: {name} out of range, got {getattr(self, name)!r}")
        for name in ("travel_x_mm", "travel_y_mm"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"MachineSimSettings: {name} must be (lo, hi) with lo < hi, got {(lo, hi)!r}")

    @property
    def max_file_bytes(self) -> int:
        """The largest job file the machine reads."""
        return self.max_points * _BYTES_PER_POINT + 65_536

    def tool(self, pixel_mm: float) -> GaussianTool:
        """The real tool (with its width and rate errors) on a grid of ``pixel_mm``."""
        return GaussianTool(self.tif_fwhm_mm * (1 + self.width_error),
                            self.tif_peak_rate_nm_s * (1 + self.rate_error), pixel_mm)


@dataclass(frozen=True)
class MachineSnapshot:
    """The machine block's contents: state, reason, job id, points done, point count."""

    state: JobState
    reason: StopReason
    job_id: int
    points_done: int
    point_count: int


@dataclass
class _Run:
    job: MachineJob
    executed_s: NDArray[np.float64] = field(repr=False)
    points_done: int = 0


class PolishingMachine:
    """The simulated machine (see the module docstring); thread-safe.

    Parameters
    ----------
    settings
        Job folder, speed, tool, limits.
    target
        What it polishes; None: it runs jobs without removing anything (progress only).
    """

    def __init__(self, settings: MachineSimSettings, target: RemovalTarget | None = None) -> None:
        self.settings = settings
        self.target = target
        self._lock = threading.Lock()
        self._state = JobState.IDLE
        self._reason = StopReason.NONE
        self._job_id = 0
        self._announced: tuple[int, int, int, float] | None = None
        self._run: _Run | None = None
        self._used: set[int] = set()
        self._executed: dict[int, NDArray[np.float64]] = {}
        self._thread: threading.Thread | None = None
        self._halt = threading.Event()
        self._halt_reason = StopReason.NONE
        self._interlock: Callable[[], StopReason | None] = lambda: None
        self._refusal = ""

    # ----------------------------------------------------------------------------- ground truth
    def snapshot(self) -> MachineSnapshot:
        """The machine block now."""
        with self._lock:
            run = self._run
            return MachineSnapshot(self._state, self._reason, self._job_id, run.points_done if run else 0,
                                   run.job.point_count if run else (self._announced[2] if self._announced else 0))

    @property
    def used_job_ids(self) -> frozenset[int]:
        """Every job id the machine has loaded (never loaded again)."""
        with self._lock:
            return frozenset(self._used)

    @property
    def last_refusal(self) -> str:
        """The message of the last refused load ('' if none)."""
        with self._lock:
            return self._refusal

    def executed_dwell_s(self, job_id: int) -> NDArray[np.float64]:
        """Dwell actually executed per point of a run job, s, shape (K,) (zeros where it never got)."""
        with self._lock:
            return self._executed[job_id].copy()

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until no job thread runs; True if none does."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout_s)
        return thread is None or not thread.is_alive()

    # ----------------------------------------------------------------------------- PLC requests
    def attach_interlock(self, interlock: Callable[[], StopReason | None]) -> None:
        """The PLC's interlock, polled between slices: a reason (e-stop, watchdog) stops the run."""
        self._interlock = interlock

    def load(self, job_id: int, crc32: int, point_count: int, total_dwell_s: float) -> bool:
        """Action LOAD; False when refused outright (busy running), else the state tells the outcome."""
        announced = (job_id, crc32, point_count, total_dwell_s)
        with self._lock:
            if self._state is JobState.RUNNING:
                return False
            if self._state is JobState.LOADED and self._announced == announced:
                return True  # a retry of the load that succeeded
            self._announced, self._job_id, self._run = announced, job_id, None
            try:
                if job_id in self._used:
                    raise JobFileRefused(StopReason.JOB_ID_USED, f"job id {job_id} was loaded before")
                job = read_job_file(self.settings.job_folder / f"job-{job_id:05d}.wsjob",
                                    self.settings.max_file_bytes)
                self._check(job, announced)
            except JobFileRefused as refusal:
                self._enter(JobEvent.LOAD_REFUSED, refusal.reason)
                self._refusal = refusal.message
                _log.warning("machine: job %d refused: %s", job_id, refusal)
                return True
            self._used.add(job_id)
            self._run = _Run(job, np.zeros(job.point_count))
            self._enter(JobEvent.LOAD_OK, StopReason.NONE)
            _log.info("machine: job %d loaded (%d points, %.3f s dwell)", job_id, job.point_count, job.total_dwell_s)
            return True

    def start(self, job_id: int) -> bool:
        """Action START; False (exception 3) unless ``job_id`` is loaded, or already started (a retry)."""
        with self._lock:
            if self._job_id == job_id and self._state in (JobState.RUNNING, JobState.DONE, JobState.ABORTED):
                return True
            if self._state is not JobState.LOADED or self._job_id != job_id or self._run is None:
                return False
            self._enter(JobEvent.START, StopReason.NONE)
            self._halt.clear()
            self._halt_reason = StopReason.NONE
            run = self._run
            self._executed[job_id] = run.executed_s
            self._thread = threading.Thread(target=self._polish_safely, args=(run,), name=f"polishing-job-{job_id}",
                                            daemon=True)
            self._thread.start()
            return True

    def abort(self, job_id: int) -> bool:
        """Action ABORT of ``job_id`` (running or loaded); False (exception 3) for another id."""
        with self._lock:
            if self._job_id != job_id:
                return False
            if self._state is JobState.LOADED:
                self._enter(JobEvent.STOP, StopReason.HOST_ABORT)
        self.stop(StopReason.HOST_ABORT)
        return True

    def stop(self, reason: StopReason) -> None:
        """Stop a running job (e-stop, watchdog trip, PLC restart, abort); it ends ABORTED with ``reason``."""
        with self._lock:
            if self._state is JobState.RUNNING and not self._halt.is_set():
                self._halt_reason = reason
                self._halt.set()

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop any run (PLC_RESTART) and join its thread."""
        self.stop(StopReason.PLC_RESTART)
        if not self.wait_idle(timeout_s):
            raise TimeoutError(f"the polishing job thread did not stop within {timeout_s} s")

    # ----------------------------------------------------------------------------- internals
    def _enter(self, event: JobEvent, reason: StopReason) -> None:
        state = next_state(self._state, event)
        if state is None:
            raise RuntimeError(f"machine: {event.value} is not allowed in state {self._state.name}")
        self._state, self._reason = state, reason

    def _check(self, job: MachineJob, announced: tuple[int, int, int, float]) -> None:
        job_id, crc32, count, total = announced
        s = self.settings
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

    def _polish_safely(self, run: _Run) -> None:
        """The job thread: :meth:`_polish`; anything that escapes it ends the job ABORTED (MACHINE_FAULT)."""
        try:
            self._polish(run)
        except Exception:
            _log.exception("machine: job %d failed; it ends ABORTED (MACHINE_FAULT)", run.job.job_id)
            with self._lock:
                if self._state is JobState.RUNNING:
                    self._enter(JobEvent.STOP, StopReason.MACHINE_FAULT)

    def _polish(self, run: _Run) -> None:
        """The job thread: travel and dwell point by point, chunks applied as it goes."""
        job, s = run.job, self.settings
        rng = np.random.default_rng([s.seed, job.job_id])
        efficiency = 1.0 + s.efficiency_spread * rng.uniform(-1.0, 1.0, job.point_count)
        target = self.target
        tool = s.tool(target.pixel_mm) if target is not None else None
        chunk = np.zeros(target.shape) if target is not None else None
        clock = _SimClock(s.time_scale, self._halt, self._stop_reason)
        chunk_dwell, last_flush = 0.0, time.monotonic()
        x, y, reason = 0.0, 0.0, StopReason.NONE
        for k in range(job.point_count):
            reason = clock.advance(math.hypot(job.x_mm[k] - x, job.y_mm[k] - y) / job.feed_mm_s[k])
            x, y = job.x_mm[k], job.y_mm[k]
            executed = 0.0
            while reason is StopReason.NONE and executed < job.dwell_s[k]:
                step = min(job.dwell_s[k] - executed, _SLICE_REAL_S * s.time_scale)
                reason = clock.advance(step)
                executed += step if reason is StopReason.NONE else 0.0
            run.executed_s[k] = executed
            chunk_dwell += executed
            if tool is not None and chunk is not None:
                tool.deposit(chunk, x, y, executed * efficiency[k])
            if reason is not StopReason.NONE:
                break
            if time.monotonic() - last_flush >= s.flush_s:
                chunk = self._flush(run, chunk, chunk_dwell, k + 1, rng)
                chunk_dwell, last_flush = 0.0, time.monotonic()
        done = job.point_count if reason is StopReason.NONE else k  # point k was under way: not done
        self._flush(run, chunk, chunk_dwell, done, rng)
        with self._lock:
            self._enter(JobEvent.FINISH if reason is StopReason.NONE else JobEvent.STOP, reason)
        _log.info("machine: job %d %s after %d/%d points", job.job_id, self._state.name, done, job.point_count)

    def _stop_reason(self) -> StopReason:
        """Why the run must stop now (a halt request, or the PLC's interlock), or NONE."""
        if self._halt.is_set():
            return self._halt_reason
        return self._interlock() or StopReason.NONE

    def _flush(self, run: _Run, chunk: NDArray[np.float64] | None, chunk_dwell: float, points_done: int,
               rng: np.random.Generator) -> NDArray[np.float64] | None:
        """Apply the chunk to the target and publish the progress; a fresh chunk."""
        if chunk is not None and self.target is not None and chunk_dwell > 0:
            if self.settings.noise_nm > 0:
                touched = chunk > 0
                scale = self.settings.noise_nm * math.sqrt(chunk_dwell / max(run.job.total_dwell_s, 1e-300))
                chunk[touched] += scale * rng.standard_normal(int(np.count_nonzero(touched)))
            self.target.apply_removal(chunk)
            chunk = np.zeros(self.target.shape)
        with self._lock:
            run.points_done = points_done
        return chunk


class _SimClock:
    """Simulated time, paced against the real clock; waits on the halt event so a stop is seen at once."""

    def __init__(self, time_scale: float, halt: threading.Event, stop_reason: Callable[[], StopReason]) -> None:
        self._scale, self._halt, self._stop_reason = time_scale, halt, stop_reason
        self._start, self._sim_s = time.monotonic(), 0.0

    def advance(self, sim_s: float) -> StopReason:
        """Let ``sim_s`` simulated seconds pass (waiting on the halt event); the reason to stop, or NONE."""
        self._sim_s += sim_s
        wait = self._start + self._sim_s / self._scale - time.monotonic()
        if wait > 0:
            self._halt.wait(wait)
        return self._stop_reason()


def _close(a: float, b: float) -> bool:
    """Equal to float32 precision of an announced value (relative 1e-6, absolute 1e-6 s)."""
    return abs(a - b) <= 1e-6 * max(1.0, abs(a), abs(b))


def _within(values: NDArray[np.float64], span: tuple[float, float]) -> bool:
    return bool(np.all((values >= span[0]) & (values <= span[1])))
