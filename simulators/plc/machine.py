"""The simulated polishing machine behind the PLC: loads job files, checks them, polishes point by point.

The PLC program hands it the job block's actions (:mod:`.program`); the machine:

- on LOAD goes LOADING at once and reads ``job-NNNNN.wsjob`` from its job folder on a loader
  thread, never on the thread that serves the PLC (a 500,000-point file takes seconds to check:
  the PLC keeps answering, the watchdog keeps counting). A file above :data:`IN_THREAD_BYTES` is
  parsed in a child process: the JSON parser holds the interpreter lock for the whole parse (1.7 s
  for 300,000 points on the loaded 2-core machine), which would starve the PLC's thread just the
  same. Its own reader (:mod:`.job_file`, regular files only, never waiting on a FIFO) and its checks of the file's CRC-32 against the announced
  one, the job id, point count and total dwell against the announced values, then its own limits
  (points, total dwell, per-point dwell, feed, travel); any failure puts it in FAULT with the
  reason code, success in LOADED. A job id it loaded before is refused (JOB_ID_USED): it never runs
  an id twice. A LOAD identical to the loaded (or loading) job is a retry: no-op; another LOAD
  while loading is busy; an abort while loading ends ABORTED and the check's outcome is dropped.
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
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.plc.job_file import JobFileRefused, MachineJob
from wavestack.simulators.plc.job_load import check_job, read_announced_job
from wavestack.simulators.plc.job_state import JobEvent, JobState, StopReason, next_state
from wavestack.simulators.plc.machine_tif import GaussianTool

__all__ = ["MachineSimSettings", "MachineSnapshot", "PolishingMachine", "RemovalTarget"]

_log = logging.getLogger(__name__)

#: Jobs whose executed dwell the machine keeps for tests (the newest; a long run must not grow without bound).
EXECUTED_HISTORY = 64
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
    job_key
        The machine's job key: it reads only job files whose HMAC-SHA256 matches (None: any).
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
    job_key: bytes | None = field(default=None, repr=False)

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
        self._executed: OrderedDict[int, NDArray[np.float64]] = OrderedDict()  # the newest EXECUTED_HISTORY jobs
        self._thread: threading.Thread | None = None
        self._halt = threading.Event()
        self._halt_reason = StopReason.NONE
        self._interlock: Callable[[], StopReason | None] = lambda: None
        self._refusal = ""
        self._loader: threading.Thread | None = None
        self._load_number = 0  # which load the loader thread's outcome belongs to

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
        """Dwell actually executed per point of a run job, s, shape (K,) (zeros where it never got).

        Kept for the newest :data:`EXECUTED_HISTORY` jobs run; KeyError for any other id.
        """
        with self._lock:
            return self._executed[job_id].copy()

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until no job or loader thread runs; True if none does."""
        deadline = time.monotonic() + timeout_s
        for thread in (self._thread, self._loader):
            if thread is not None:
                thread.join(max(0.0, deadline - time.monotonic()))
        return not any(t is not None and t.is_alive() for t in (self._thread, self._loader))

    # ----------------------------------------------------------------------------- PLC requests
    def attach_interlock(self, interlock: Callable[[], StopReason | None]) -> None:
        """The PLC's interlock, polled between slices: a reason (e-stop, watchdog) stops the run."""
        self._interlock = interlock

    def load(self, job_id: int, crc32: int, point_count: int, total_dwell_s: float) -> bool:
        """Action LOAD; False when refused outright (busy running or loading another), else the state tells.

        Returns at once: the machine is LOADING until its loader thread has read and checked the file.
        """
        announced = (job_id, crc32, point_count, total_dwell_s)
        with self._lock:
            if self._state in (JobState.LOADED, JobState.LOADING) and self._announced == announced:
                return True  # a retry of the load that succeeded or is under way
            if self._state in (JobState.RUNNING, JobState.LOADING):
                return False
            self._announced, self._job_id, self._run = announced, job_id, None
            self._enter(JobEvent.LOAD, StopReason.NONE)
            self._load_number += 1
            if job_id in self._used:
                self._finish_load(self._load_number, JobFileRefused(StopReason.JOB_ID_USED,
                                                                    f"job id {job_id} was loaded before"))
                return True
            self._loader = threading.Thread(target=self._load, args=(self._load_number, announced),
                                            name=f"job-loader-{job_id}", daemon=True)
            self._loader.start()
        return True

    def _load(self, number: int, announced: tuple[int, int, int, float]) -> None:
        """The loader thread: read and check the job file, then settle the load (unless it was dropped)."""
        job_id = announced[0]
        try:
            job = read_announced_job(self.settings.job_folder / f"job-{job_id:05d}.wsjob",
                                     self.settings.max_file_bytes, self.settings.job_key)
            check_job(job, announced, self.settings)
            outcome: MachineJob | JobFileRefused = job
        except JobFileRefused as refusal:
            outcome = refusal
        except Exception as error:  # noqa: BLE001 - a bug in the checks must not leave the machine LOADING
            _log.exception("machine: checking job %d failed", job_id)
            outcome = JobFileRefused(StopReason.FILE_CORRUPT, f"job {job_id}: the check failed ({error})")
        with self._lock:
            self._finish_load(number, outcome)

    def _finish_load(self, number: int, outcome: MachineJob | JobFileRefused) -> None:
        """LOADED or FAULT for load ``number``; nothing when it is no longer the one loading (lock held)."""
        if number != self._load_number or self._state is not JobState.LOADING:
            return  # aborted, or superseded, while the file was read
        if isinstance(outcome, JobFileRefused):
            self._enter(JobEvent.LOAD_REFUSED, outcome.reason)
            self._refusal = outcome.message
            _log.warning("machine: job %d refused: %s", self._job_id, outcome)
            return
        self._used.add(outcome.job_id)
        self._run = _Run(outcome, np.zeros(outcome.point_count))
        self._enter(JobEvent.LOAD_OK, StopReason.NONE)
        _log.info("machine: job %d loaded (%d points, %.3f s dwell)", outcome.job_id, outcome.point_count,
                  outcome.total_dwell_s)

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
            while len(self._executed) > EXECUTED_HISTORY:  # bounded: a shift of jobs must not grow without end
                self._executed.popitem(last=False)
            self._thread = threading.Thread(target=self._polish_safely, args=(run,), name=f"polishing-job-{job_id}",
                                            daemon=True)
            self._thread.start()
            return True

    def abort(self, job_id: int) -> bool:
        """Action ABORT of ``job_id`` (running or loaded); False (exception 3) for another id."""
        with self._lock:
            if self._job_id != job_id:
                return False
            if self._state in (JobState.LOADED, JobState.LOADING):
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
        """Stop any run (PLC_RESTART) and join its thread and the loader's."""
        self.stop(StopReason.PLC_RESTART)
        if not self.wait_idle(timeout_s):
            raise TimeoutError(f"the polishing job or loader thread did not stop within {timeout_s} s")

    # ----------------------------------------------------------------------------- internals
    def _enter(self, event: JobEvent, reason: StopReason) -> None:
        state = next_state(self._state, event)
        if state is None:
            raise RuntimeError(f"machine: {event.value} is not allowed in state {self._state.name}")
        self._state, self._reason = state, reason

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
