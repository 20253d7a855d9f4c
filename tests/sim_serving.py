"""Run a ``wavestack sim`` simulator's entry point in a thread, as the CLI does, for a test."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any


def serve_in_thread(runner: Callable[..., None], config: Any, name: str
                    ) -> tuple[threading.Thread, threading.Event, int, list[str]]:
    """Start ``runner(config, "127.0.0.1", 0, False, announce, stop)``; returns thread, stop, port, announcements.

    Raises AssertionError (after stopping the thread) if nothing is announced within 10 s, or if the
    first line is not ``listening 127.0.0.1:PORT``.
    """
    lines: queue.Queue[str] = queue.Queue()
    announced: list[str] = []
    stop = threading.Event()

    def announce(line: str) -> None:
        announced.append(line)
        lines.put(line)

    thread = threading.Thread(target=runner, args=(config, "127.0.0.1", 0, False, announce, stop), name=name)
    thread.start()
    try:
        line = lines.get(timeout=10.0)
    except queue.Empty:
        stop.set()
        thread.join()
        raise AssertionError("the simulator announced nothing") from None
    if not line.startswith("listening 127.0.0.1:"):
        stop.set()
        thread.join()
        raise AssertionError(f"unexpected announcement {line!r}")
    return thread, stop, int(line.rsplit(":", 1)[1]), announced
