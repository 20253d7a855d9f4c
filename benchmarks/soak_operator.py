"""The soak's operator: re-arms a tripped PLC watchdog the way ``wavestack plc rearm`` does.

By design (issue 13) only an operator recovers a PLC watchdog trip: a second, *monitor* link
(``PolishingLink(..., monitor=True)``: no heartbeat, no command) writes the re-arm register, and the
running station sees the PLC healthy at its next heartbeat and resumes its commands. The soak's
operator does the same ``delay_s`` after the trip was first seen (0: never), retries a failed
attempt (the PLC may still be out) every ``retry_s``, and remembers each re-arm with the number of
commands the PLC had accepted, so the report can show that commands flowed again after it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from wavestack.drivers.plc import PolishingLink

__all__ = ["Operator", "Rearm"]


@dataclass(frozen=True)
class Rearm:
    """One operator re-arm: when (s since the start), of which station, after how long tripped (s)."""

    t_s: float
    incarnation: int
    tripped_for_s: float
    accepted_before: int
    status: str


class Operator:
    """Re-arms a tripped PLC watchdog through a monitor link after ``delay_s``; never when ``delay_s`` is 0."""

    def __init__(self, link_settings: Any, delay_s: float, timeout_s: float = 2.0, retry_s: float = 1.0) -> None:
        self._settings, self.delay_s, self._timeout_s, self._retry_s = link_settings, delay_s, timeout_s, retry_s
        self._next_attempt_s = 0.0
        self.rearms: list[Rearm] = []
        self.errors: list[str] = []

    def due(self, t_s: float, tripped_since_s: float | None) -> bool:
        """Whether the operator would act now on a watchdog tripped since ``tripped_since_s`` (None: not tripped)."""
        return self.delay_s > 0 and tripped_since_s is not None and t_s - tripped_since_s >= self.delay_s \
            and t_s >= self._next_attempt_s

    def rearm(self, plc_simulator: Any, incarnation: int, t_s: float, tripped_since_s: float) -> Rearm | None:
        """``wavestack plc rearm`` on the simulator's address; None (and an entry in ``errors``) if it failed."""
        self._next_attempt_s = t_s + self._retry_s
        settings = self._settings
        link = PolishingLink(plc_simulator.host, plc_simulator.port, settings.register_map(), settings.link_timing(),
                             monitor=True)
        try:
            with link:
                link.connect(timeout_s=self._timeout_s)
                status = link.rearm(timeout_s=self._timeout_s)
        except Exception as error:  # noqa: BLE001 - the operator tries again; a PLC that stays out shows as stuck
            self.errors.append(f"t={t_s:.1f} s: re-arm failed: {type(error).__name__}: {error}")
            return None
        rearm = Rearm(t_s, incarnation, t_s - tripped_since_s, plc_simulator.program.accepted_count,
                      "tripped" if status.watchdog_tripped else "ok")
        self.rearms.append(rearm)
        return rearm

    def accepted_after(self, plc_simulator: Any, incarnation: int) -> list[int]:
        """For each re-arm: the commands the PLC accepted after it (-1: another station's, not counted)."""
        if plc_simulator is None:
            return [-1] * len(self.rearms)
        accepted = plc_simulator.program.accepted_count  # all of them (the kept history is bounded)
        return [accepted - r.accepted_before if r.incarnation == incarnation else -1 for r in self.rearms]
