"""Which PLC watchdog trips the soak expects: a trip is *fail-safe* only after a PLC outage longer than the watchdog.

The PLC's watchdog trips when the host's heartbeat (every ``watchdog_timeout_s / 4``, see
``Station``) stops reaching it for ``watchdog_timeout_s``. A PLC fault that keeps the PLC
unreachable (a restart, down ``plc_down_s``) or unanswering within the link's ``io_timeout_s``
(replies ``plc_reply_delay_s`` late) for at least ``watchdog_timeout_s`` minus one heartbeat
period may trip it: that is the designed fail-safe, recovered by an operator re-arm. Any other
trip (after a camera or piezo fault, a short PLC fault, or no fault) is a station FAILURE.
Pure functions of the fault windows, so the rule is tested on hand-made windows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from soak_observe import Window

__all__ = ["FAILSAFE", "FAILURE", "TripLimits", "classify_trip", "plc_outage_s"]

FAILSAFE, FAILURE = "fail-safe", "FAILURE"
DETECTION_SLACK_S = 2.0  # the monitor polls every 0.5 s; a reconnect back-off adds up to 0.5 s


@dataclass(frozen=True)
class TripLimits:
    """The PLC link's timing (s) that decides which outages may trip the watchdog."""

    watchdog_timeout_s: float
    heartbeat_period_s: float
    io_timeout_s: float

    @property
    def outage_s(self) -> float:
        """Shortest outage that may trip the watchdog: its timeout minus one heartbeat period, s."""
        return self.watchdog_timeout_s - self.heartbeat_period_s

    @classmethod
    def from_link(cls, link: Any) -> TripLimits:
        """From ``[plc]`` settings; the heartbeat period is the station's (a quarter of the watchdog time)."""
        return cls(link.watchdog_timeout_s, link.watchdog_timeout_s / 4, link.io_timeout_s)


def plc_outage_s(window: Window, limits: TripLimits) -> float:
    """How long ``window``'s fault kept the PLC unreachable or unanswering within ``io_timeout_s``, s."""
    if window.plc_down_s > 0:
        return window.plc_down_s
    if window.plc_reply_delay_s > limits.io_timeout_s and window.clear_t_s is not None:
        return window.clear_t_s - window.t_s
    return 0.0


def classify_trip(t_s: float, windows: Sequence[Window], limits: TripLimits) -> tuple[str, Window]:
    """A trip noticed at ``t_s`` (s since the start): fail-safe and the outage behind it, or FAILURE.

    Fail-safe when a PLC fault that began before ``t_s`` kept the PLC out for at least
    ``limits.outage_s`` and ended at most ``watchdog_timeout_s`` (+ detection slack) before
    ``t_s``; otherwise FAILURE, charged to the last window opened before ``t_s``.

    Examples
    --------
    >>> limits = TripLimits(2.0, 0.5, 0.5)
    >>> restart = Window(0, "plc_restart", 10.0, clear_t_s=12.2, plc_down_s=2.2)
    >>> classify_trip(12.4, [Window(-1, "baseline", 0.0), restart], limits)[0]
    'fail-safe'
    >>> classify_trip(40.0, [Window(-1, "baseline", 0.0), restart], limits)[0]
    'FAILURE'
    """
    current = windows[0]
    for window in windows:
        if window.t_s > t_s:
            break
        current = window
    for window in reversed(windows):
        if window.index < 0 or window.t_s > t_s:
            continue
        end = window.clear_t_s if window.clear_t_s is not None else window.t_s
        if plc_outage_s(window, limits) >= limits.outage_s and \
                t_s <= end + limits.watchdog_timeout_s + DETECTION_SLACK_S:
            return FAILSAFE, window
    return FAILURE, current
