"""Suite-wide fixtures: every test must leave no thread and no socket behind.

Warnings are errors and each test has a timeout (see ``[tool.pytest.ini_options]`` in
pyproject.toml); this file adds the leak check that pymodbus and ophyd-async use in spirit: a
test that starts a thread or opens a socket must stop or close it before it ends.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest

import fuzz  # noqa: F401  (registers the Hypothesis profiles "ci" and "long")

_GRACE_S = 2.0  # time a finishing thread or a closing socket gets before it counts as leaked


def _open_sockets() -> set[str]:
    """Inodes of the sockets this process holds open (Linux /proc; empty set elsewhere)."""
    fd_dir = "/proc/self/fd"
    if not os.path.isdir(fd_dir):
        return set()
    found: set[str] = set()
    for name in os.listdir(fd_dir):
        try:
            target = os.readlink(os.path.join(fd_dir, name))
        except OSError:  # the descriptor closed while we listed the folder
            continue
        if target.startswith("socket:"):
            found.add(target)
    return found


def _live_threads() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t.is_alive()}


@pytest.fixture(autouse=True)
def no_leaked_threads_or_sockets() -> Iterator[None]:
    """Fail the test if it leaves a thread running or a socket open."""
    threads_before = _live_threads()
    sockets_before = _open_sockets()
    yield
    deadline = time.monotonic() + _GRACE_S
    while True:
        leaked_threads = _live_threads() - threads_before
        leaked_sockets = _open_sockets() - sockets_before
        if not (leaked_threads or leaked_sockets) or time.monotonic() > deadline:
            break
        time.sleep(0.02)
    problems = []
    if leaked_threads:
        problems.append("threads still running: " + ", ".join(sorted(t.name for t in leaked_threads)))
    if leaked_sockets:
        problems.append(f"{len(leaked_sockets)} socket(s) left open: " + ", ".join(sorted(leaked_sockets)))
    if problems:
        pytest.fail("test leaked resources; " + "; ".join(problems), pytrace=False)


@pytest.fixture
def station_factory() -> Iterator:
    """Open stations on simulated devices; everything opened is closed when the test ends.

    Calling the factory with a ``StationConfig`` returns ``(station, devices)``.
    """
    from contextlib import ExitStack

    from wavestack.station.devices import open_station_devices
    from wavestack.station.station import Station

    with ExitStack() as stack:
        def make(config):  # -> tuple[Station, StationDevices]
            devices = open_station_devices(config, stack)
            station = Station(config, devices)
            stack.callback(station.close)
            return station, devices
        yield make
