"""The exit status of a closed loop's command (``polish``, ``align``) from the loop's terminal state.

0 when the loop ended by its own rule (target, budget, no improvement, floor: the summary says
which); 3 when it faulted (one line on standard error naming the fault); 130 when the operator
stopped it (Ctrl-C, SIGTERM). The faulted and interrupted phases are the loop's state table's.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from wavestack.loop import StateTable

__all__ = ["EXIT_FAULT", "EXIT_INTERRUPTED", "loop_exit"]

EXIT_FAULT = 3
EXIT_INTERRUPTED = 130


def loop_exit(command: str, table: StateTable[Any, Any], phase: Any, reason: str | None, *,
              stream: TextIO | None = None) -> int:
    """The exit status of ``wavestack COMMAND`` ending in ``phase`` (module notes).

    Example
    -------
    >>> from wavestack.polish.state import TABLE, LoopPhase
    >>> loop_exit("polish", TABLE, LoopPhase.TARGET_MET, "RMS 4 nm <= 5 nm")
    0
    """
    if phase is table.interrupted:
        return EXIT_INTERRUPTED
    if phase is table.faulted:
        print(f"wavestack {command}: device error: {reason}", file=stream or sys.stderr)
        return EXIT_FAULT
    return 0
