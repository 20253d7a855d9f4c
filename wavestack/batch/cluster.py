"""The Dask client of a campaign: a local cluster sized to the machine, or a remote scheduler.

Processes, not threads: the work is CPU-bound numpy, and parts of it hold the GIL (the phase
stage's per-pixel Python-level steps, the fitters' small matrix products, h5py, which serialises
every call behind one lock), so threads in one process would share one core for much of a set.
Each worker is one process with one thread, and BLAS is kept to one thread (``wavestack.cli``
sets it before numpy loads; spawned workers inherit the environment).

Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` in the workers it spawns (to hand memory back to
the system sooner). glibc then trims and re-maps the heap around every large temporary array:
measured on the small station, a recording's analysis took 1.8-2x as long with it (fitter builds
0.35 s -> 0.65-0.70 s). The local cluster's workers are spawned without it.

Dask's housekeeping costs CPU in every process, all the time: the event loop's tick check every
20 ms, each worker's statistical profiler (a stack sample of the running task every 10 ms), the
scheduler's work stealing (a balance pass every 100 ms) and the system and memory monitors.
Measured on an idle 2-worker local cluster: ~4 % of a core in the client process (which holds the
scheduler and the nannies) and ~2.5 % in each worker; with :data:`QUIET_CONFIG` ~1 % and ~0.5 %.
On a machine with one core per worker that CPU is taken from the workers, so the local cluster
runs with it. None of it changes what is computed: a campaign's tasks are independent and of one
kind (nothing to steal or to profile).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Final

from wavestack.pipeline import InputError

logger = logging.getLogger(__name__)

#: Longest wait for the first worker of a remote scheduler, seconds.
WORKER_WAIT_S: Final = 60.0

#: Dask settings of the local cluster (module notes): less housekeeping, nothing computed differently.
QUIET_CONFIG: Final = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.profile.enabled": False,
    "distributed.scheduler.work-stealing": False,
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def local_workers(requested: int | None) -> int:
    """Workers for a local cluster: ``requested``, else one per CPU this process may use."""
    if requested is not None:
        return requested
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def campaign_client(scheduler: str | None, workers: int | None) -> Iterator[object]:
    """A ``distributed.Client``: on a new ``LocalCluster`` of ``workers`` single-threaded
    processes (``scheduler`` None), or connected to ``scheduler`` (``tcp://HOST:8786``); closed,
    and the local cluster shut down, on exit.

    Raises
    ------
    InputError
        The scheduler cannot be reached, or has no worker within :data:`WORKER_WAIT_S`.
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler is None:
        n = local_workers(workers)
        logger.info("starting a local cluster of %d worker processes", n)
        with dask.config.set(QUIET_CONFIG), LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                     silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError) as error:
        raise InputError(f"{scheduler}: cannot reach the Dask scheduler ({error})") from error
    with client:
        try:
            client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except TimeoutError as error:
            raise InputError(f"{scheduler}: no Dask worker joined within {WORKER_WAIT_S:g} s") from error
        yield client
