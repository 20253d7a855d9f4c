"""One long-lived thread per role (a camera's stream reader, a station's phase stepping), reused across restarts.

Why. Each new thread gets its own glibc malloc arena (``man 3 mallopt``, ``M_ARENA_MAX``), and an
arena keeps the heap its thread grew: its top is not given back by ``malloc_trim`` and it goes,
with whatever it holds, to the next new thread that picks it from glibc's free list. A reader or
stepping thread started afresh at every camera reconnect lands in whichever arena is free, so the
memory resident after a reconnect depends on the arena it got: issue 13's soak saw RSS move by
10-40 MB at each camera reconnect (``docs/faults.md``, "Camera reconnects", for the probes). A
role's jobs run one after the other on the same thread, so they stay in the same arena.

A job submitted while the previous one still runs (a stop that timed out) gets a thread of its
own, as before, so a stuck job never blocks the next one.
"""

from __future__ import annotations

import logging
import queue
import sys
import threading
from collections.abc import Callable

__all__ = ["Job", "RoleThread"]

_log = logging.getLogger(__name__)
_CLOSE = None  # the sentinel that ends the role's thread


class Job:
    """One run of a target on a :class:`RoleThread` (or, when the role was busy, on a thread of its own).

    Example
    -------
    >>> role = RoleThread("example")
    >>> job = role.run(lambda: None)
    >>> job.join(5.0); job.is_alive()
    False
    >>> role.close()
    """

    def __init__(self, target: Callable[[], None], name: str) -> None:
        self._target = target
        self.name = name
        self._done = threading.Event()
        self._started = False

    def _run(self) -> None:
        try:
            self._target()
        except BaseException:  # reported as an exception in a thread is, then the role goes on
            threading.excepthook(threading.ExceptHookArgs((*sys.exc_info(), threading.current_thread())))
        finally:
            self._target = _finished  # the job keeps nothing its target referenced
            self._done.set()

    def join(self, timeout: float | None = None) -> None:
        """Wait until the target has returned (or ``timeout`` s have passed, when given)."""
        self._done.wait(timeout)

    def is_alive(self) -> bool:
        """True from :meth:`RoleThread.run` until the target has returned."""
        return self._started and not self._done.is_set()


def _finished() -> None:
    """What a finished job's target becomes."""


class RoleThread:
    """A long-lived thread that runs its role's jobs one at a time; started at the first job.

    Parameters
    ----------
    name : str
        The thread's name (one per role, e.g. ``"u3v-reader SN"``).
    daemon : bool
        As :class:`threading.Thread`'s.

    Example
    -------
    >>> role = RoleThread("example")
    >>> seen = []
    >>> for k in range(3):
    ...     role.run(lambda k=k: seen.append((k, threading.current_thread().name))).join(5.0)
    >>> seen
    [(0, 'example'), (1, 'example'), (2, 'example')]
    >>> role.close()
    """

    def __init__(self, name: str, *, daemon: bool = False) -> None:
        self._name = name
        self._daemon = daemon
        self._lock = threading.Lock()
        self._jobs: queue.SimpleQueue[Job | None] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._current: Job | None = None
        self._closed = False

    @property
    def name(self) -> str:
        return self._name

    @property
    def ident(self) -> int | None:
        """The role's thread id (None before the first job): the same for every job while not busy."""
        with self._lock:
            return None if self._thread is None else self._thread.ident

    def run(self, target: Callable[[], None]) -> Job:
        """Run ``target`` on the role's thread (on a thread of its own if a job still runs there).

        Raises
        ------
        RuntimeError
            The role was closed.
        """
        job = Job(target, self._name)
        with self._lock:
            if self._closed:
                raise RuntimeError(f"{self._name}: the role's thread was closed; expected run() before close()")
            job._started = True
            if self._current is not None and self._current.is_alive():
                _log.info("%s: the previous job still runs; this one gets a thread of its own", self._name)
                threading.Thread(target=job._run, name=self._name, daemon=self._daemon).start()
                return job
            self._current = job
            if self._thread is None:
                self._thread = threading.Thread(target=self._serve, name=self._name, daemon=self._daemon)
                self._thread.start()
        self._jobs.put(job)
        return job

    def _serve(self) -> None:
        while (job := self._jobs.get()) is not _CLOSE:
            job._run()
            del job  # nothing of the last job stays referenced while the thread waits

    def close(self, timeout_s: float | None = None) -> None:
        """End the role's thread after its current job (joined within ``timeout_s``); idempotent."""
        with self._lock:
            thread, self._closed = self._thread, True
        if thread is None:
            return
        self._jobs.put(_CLOSE)
        thread.join(timeout_s)
        if thread.is_alive():
            _log.error("%s: the role's thread still runs %s s after close", self._name, timeout_s)
