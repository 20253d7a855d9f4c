"""Give freed heap memory back to the operating system, at most once per period.

Why. A frame set passes through a dozen arrays of 2-10 MB on two threads (the camera's reader and
the result loop). glibc serves each from its heap or, above its *dynamic* mmap threshold, from
``mmap``; every ``free`` of an mmapped block raises the threshold to that block's size (up to
32 MiB on 64-bit), so after a few cycles every frame-sized array comes from the heaps of the
threads' arenas. When a fault changes the timing (a PLC that stops answering, a camera stall),
the arrays' lifetimes interleave differently, holes appear that the next arrays do not fit, and
the heaps grow to a new high-water mark that glibc keeps: the soak saw RSS step up by ~100 MB per
burst of faults with nothing leaking (tracemalloc flat, ``README.md``, "Faults and safety").
Pinning the threshold low (``MALLOC_MMAP_THRESHOLD_``) stops the steps but sends every array
through ``mmap`` and its page faults: the pipeline's CPU per result rose 30 -> 42 ms.

``malloc_trim(0)`` walks the arenas and returns the whole free pages inside them (``madvise``),
not only the heap's top (glibc >= 2.8, ``man 3 malloc_trim``). Once per second it costs ~1 ms
(median of 140 calls measured in a frozen-echo soak), and RSS then follows the memory really in
use instead of its largest ever fragmentation.

On a C library without ``malloc_trim`` (musl, macOS, Windows) :class:`HeapRelease` does nothing.

After a device fault (:meth:`HeapRelease.after_fault`) the station also runs the cyclic garbage
collector. A device error stored for later and raised again (a closed frame ring's close error, a
driver's disconnect error) is in a reference cycle with the frames of its own traceback, and those
frames keep their callers' locals alive: the acquisition thread's half-read set, the rings that
held frames, ~20-60 MB per camera or piezo fault on the default station (``gc.garbage`` in issue
13's fourth session). Only the cyclic collector frees such a cycle, and it runs when *container*
allocations pile up, which a loop of a few numpy arrays per result rarely does: the soak saw the
garbage of a few minutes of faults (+130 MB) freed at once by one collection. The station
collects once per outage, after the first result when its devices are back: a full collection
of ~113,000 objects took 310-410 ms on the loaded 2-core machine (load 15), too long to repeat at
every lost-device cycle of a flapping camera.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import time
from collections.abc import Callable

__all__ = ["HeapRelease", "glibc_malloc_trim"]

_log = logging.getLogger(__name__)


def glibc_malloc_trim() -> Callable[[], None] | None:
    """glibc's ``malloc_trim(0)`` as a callable, or None where the C library has no such function.

    Example
    -------
    >>> trim = glibc_malloc_trim()
    >>> trim is None or callable(trim)
    True
    """
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        function = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):
        return None
    function.argtypes, function.restype = [ctypes.c_size_t], ctypes.c_int

    def trim() -> None:
        function(0)

    return trim


class HeapRelease:
    """Call a heap trim at most once per ``period_s`` seconds of the caller's clock; collect cycles after faults.

    Parameters
    ----------
    period_s : float
        Least time between two trims, s; 0 never trims.
    trim : callable or None
        What trims; default glibc's ``malloc_trim(0)`` (None on other C libraries: never trims).
    collect : callable
        The full cyclic garbage collection of :meth:`after_fault`; default :func:`gc.collect`.

    Example
    -------
    >>> calls = []
    >>> release = HeapRelease(1.0, trim=lambda: calls.append(1))
    >>> [release.maybe_release(t) for t in (0.0, 0.5, 1.0, 1.2, 2.1)]
    [True, False, True, False, True]
    >>> collected = []
    >>> release = HeapRelease(1.0, trim=lambda: calls.append(1), collect=lambda: collected.append(1))
    >>> release.after_fault(5.0)
    >>> len(collected), release.maybe_release(5.5), release.maybe_release(6.0)
    (1, False, True)
    """

    def __init__(self, period_s: float, trim: Callable[[], None] | None = None,
                 collect: Callable[[], object] = gc.collect) -> None:
        if not period_s >= 0.0:
            raise ValueError(f"period_s: expected a number >= 0 s, got {period_s!r}")
        self._period_s = period_s
        self._trim = trim if trim is not None else (glibc_malloc_trim() if period_s > 0 else None)
        self._collect = collect
        self._last_s: float | None = None
        if period_s > 0 and self._trim is None:
            _log.info("this C library has no malloc_trim: freed heap memory stays with the process")

    def maybe_release(self, now_s: float) -> bool:
        """Trim if ``period_s`` has passed since the last trim (or never trimmed); True if it did."""
        if self._trim is None or self._period_s <= 0:
            return False
        if self._last_s is not None and now_s - self._last_s < self._period_s:
            return False
        self._last_s = now_s
        self._trim()
        return True

    def after_fault(self, now_s: float) -> None:
        """The devices are back after a fault: collect the reference cycles its errors left, then trim (if trimming).

        Parameters
        ----------
        now_s : float
            The caller's clock, s (the trim counts as this period's).
        """
        started = time.perf_counter()
        self._collect()
        _log.debug("cyclic garbage collected after a device fault in %.1f ms", (time.perf_counter() - started) * 1e3)
        if self._trim is not None and self._period_s > 0:
            self._last_s = now_s
            self._trim()
