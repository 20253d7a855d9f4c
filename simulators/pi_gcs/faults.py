"""Fault switches of the simulated GCS controller, flipped by tests or an operator while it serves.

One-shot faults hit the next ``n`` commands (optionally only one mnemonic, e.g. ``"MOV"``):

* ``fail_next(code)``: the command is not executed and sets error ``code`` (a query then sends no
  answer, as for any failing query);
* ``drop_connection()``: the command is not executed and the TCP connection it came on closes;
* ``split_replies(pieces, gap_s)``: the answer arrives in ``pieces`` chunks ``gap_s`` apart (a
  driver must reassemble it; the bytes are complete);
* ``truncate_replies(keep_bytes)``: only the first ``keep_bytes`` of the answer are sent, the rest
  never (a driver must time out, never accept half a line).

Lasting faults: ``slow_factor`` (every move takes that many times longer) and ``stuck_axes`` (those
axes never leave their start position in later moves, so they never report on target). A fault
set during a move applies from the next ``MOV``. All methods are thread-safe.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass

__all__ = ["GcsSimFaults", "ReplyFault"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReplyFault:
    """A one-shot fault taken for one command: its kind and parameters."""

    kind: str
    code: int = 0
    pieces: int = 1
    gap_s: float = 0.0
    keep_bytes: int = 0


@dataclass
class _OneShot:
    fault: ReplyFault
    remaining: int
    mnemonic: str | None


class GcsSimFaults:
    """Switches that make the simulated controller misbehave (see the module docstring).

    Attributes
    ----------
    slow_factor
        Every move's duration is multiplied by this (>= 1; 1 = normal).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._one_shots: list[_OneShot] = []
        self._stuck: set[str] = set()
        self._slow_factor = 1.0

    # ------------------------------------------------------------------ lasting faults
    @property
    def slow_factor(self) -> float:
        """Move duration multiplier (>= 1)."""
        with self._lock:
            return self._slow_factor

    @slow_factor.setter
    def slow_factor(self, factor: float) -> None:
        if not 1.0 <= factor < math.inf:
            raise ValueError(f"slow_factor must be >= 1 and finite, got {factor}")
        with self._lock:
            self._slow_factor = float(factor)

    @property
    def stuck_axes(self) -> frozenset[str]:
        """Axes that do not move in later moves."""
        with self._lock:
            return frozenset(self._stuck)

    def stick_axis(self, axis: str) -> None:
        """From the next move on, ``axis`` stays where it is and never reports on target."""
        with self._lock:
            self._stuck.add(axis)

    def release_axis(self, axis: str) -> None:
        """Undo :meth:`stick_axis` (from the next move on)."""
        with self._lock:
            self._stuck.discard(axis)

    # ------------------------------------------------------------------ one-shot faults
    def fail_next(self, code: int, n: int = 1, *, command: str | None = None) -> None:
        """The next ``n`` commands (other than ``ERR?``; of mnemonic ``command`` if given) fail with ``code``."""
        if code <= 0:
            raise ValueError(f"code must be a nonzero GCS error code > 0, got {code}")
        self._add(ReplyFault("fail", code=code), n, command)

    def drop_connection(self, n: int = 1, *, command: str | None = None) -> None:
        """The next ``n`` commands are not executed; the connection they arrived on closes."""
        self._add(ReplyFault("drop"), n, command)

    def split_replies(self, n: int = 1, *, pieces: int = 3, gap_s: float = 0.02, command: str | None = None) -> None:
        """The answers to the next ``n`` commands arrive in ``pieces`` chunks, ``gap_s`` apart."""
        if pieces < 2 or not 0.0 <= gap_s <= 10.0:
            raise ValueError(f"expected pieces >= 2 and 0 <= gap_s <= 10, got {pieces}, {gap_s}")
        self._add(ReplyFault("split", pieces=pieces, gap_s=gap_s), n, command)

    def truncate_replies(self, n: int = 1, *, keep_bytes: int = 2, command: str | None = None) -> None:
        """Only the first ``keep_bytes`` of the next ``n`` answers are sent."""
        if keep_bytes < 0:
            raise ValueError(f"keep_bytes must be >= 0, got {keep_bytes}")
        self._add(ReplyFault("truncate", keep_bytes=keep_bytes), n, command)

    def clear(self) -> None:
        """Switch every fault off."""
        with self._lock:
            self._one_shots.clear()
            self._stuck.clear()
            self._slow_factor = 1.0

    @property
    def pending(self) -> int:
        """One-shot faults not yet used."""
        with self._lock:
            return sum(shot.remaining for shot in self._one_shots)

    def take(self, mnemonic: str, kinds: tuple[str, ...]) -> ReplyFault | None:
        """The first one-shot fault of one of ``kinds`` that hits a command with ``mnemonic`` (upper case), used up."""
        with self._lock:
            for shot in self._one_shots:
                if shot.fault.kind not in kinds:
                    continue
                if shot.mnemonic == mnemonic or (shot.mnemonic is None and mnemonic != "ERR?"):
                    shot.remaining -= 1
                    if shot.remaining <= 0:
                        self._one_shots.remove(shot)
                    _log.warning("GCS simulator fault: %s on %s", shot.fault.kind, mnemonic)
                    return shot.fault
        return None

    def _add(self, fault: ReplyFault, n: int, command: str | None) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        with self._lock:
            self._one_shots.append(_OneShot(fault, n, command.upper() if command else None))
