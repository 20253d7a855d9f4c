"""A PLC communication watchdog, as a pure state machine (the caller passes the clock).

Real PLCs guard remote control with a "heartbeat" or "life sign" watchdog: the host must keep
changing a register; if the value stays the same for longer than the timeout, the PLC drives its
outputs to a safe state (zero) and refuses remote requests until someone re-arms it explicitly.
Only a *change* of the heartbeat counts: reads, and writes of the same value, do not.

States: ``IDLE`` (no heartbeat change seen since start-up; outputs are zero anyway and commands
are refused) -> ``RUNNING`` (first change) -> ``TRIPPED`` (no change for ``timeout_s``) ->
``RUNNING`` again only through :meth:`HeartbeatWatchdog.rearm`.
"""

from __future__ import annotations

import enum

__all__ = ["HeartbeatWatchdog", "WatchdogState"]


class WatchdogState(enum.Enum):
    """Where the watchdog is."""

    IDLE = "idle"
    RUNNING = "running"
    TRIPPED = "tripped"


class HeartbeatWatchdog:
    """Heartbeat watchdog of the simulated PLC.

    Parameters
    ----------
    timeout_s
        Longest time without a heartbeat change before the watchdog trips, s (> 0).
    initial_value
        The heartbeat register's value at start-up; writing it again is not a change.
    """

    def __init__(self, timeout_s: float, initial_value: int = 0) -> None:
        if not timeout_s > 0:
            raise ValueError(f"watchdog timeout_s must be > 0, got {timeout_s!r}")
        self._timeout_s = float(timeout_s)
        self._value = int(initial_value)
        self._state = WatchdogState.IDLE
        self._last_change_s = 0.0
        self._trips = 0

    @property
    def timeout_s(self) -> float:
        """The timeout, s."""
        return self._timeout_s

    @property
    def state(self) -> WatchdogState:
        """The current state (as of the last :meth:`poll`)."""
        return self._state

    @property
    def trips(self) -> int:
        """How many times the watchdog has tripped."""
        return self._trips

    @property
    def value(self) -> int:
        """The last heartbeat value observed."""
        return self._value

    def observe(self, value: int, now_s: float) -> bool:
        """A heartbeat write arrived; returns True if it counted as activity (a change, not tripped)."""
        if self._state is WatchdogState.TRIPPED or value == self._value:
            return False
        self._value = int(value)
        self._last_change_s = now_s
        self._state = WatchdogState.RUNNING
        return True

    def poll(self, now_s: float) -> bool:
        """Advance to ``now_s``; returns True if the watchdog tripped in this call."""
        if self._state is WatchdogState.RUNNING and now_s - self._last_change_s > self._timeout_s:
            self._state = WatchdogState.TRIPPED
            self._trips += 1
            return True
        return False

    def rearm(self, now_s: float) -> bool:
        """Re-arm after a trip: running again, the timeout counted from ``now_s``.

        Returns True if the watchdog was tripped (a re-arm of a running watchdog changes nothing).
        """
        if self._state is not WatchdogState.TRIPPED:
            return False
        self._state = WatchdogState.RUNNING
        self._last_change_s = now_s
        return True
