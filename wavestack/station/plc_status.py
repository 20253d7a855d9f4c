"""The PLC's status as the station service publishes it: one heartbeat's outcome per cycle.

The station's thread beats the PLC's watchdog every cycle (and between slices of its waits) and
reads the status back; :class:`Heartbeat` is what it saw, carried by every result's output record
and kept by the service's :class:`~wavestack.station.live_maps.LiveMaps` for the loops (a polishing
job's wait reads a watchdog trip from it).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Heartbeat"]


@dataclass(frozen=True)
class Heartbeat:
    """One PLC heartbeat: the PLC's status, or the error that stopped the exchange.

    Attributes
    ----------
    ok : bool
        The heartbeat was written and the status read with a fresh echo.
    watchdog_tripped, ready, estop : bool or None
        From the status (``watchdog_tripped`` also when the heartbeat was refused by a trip).
    error : str or None
        Why the exchange failed.
    state : str or None
        The output's mode after this heartbeat (:class:`~wavestack.station.output_state.OutputMode`
        name, e.g. ``"ARMED"``, ``"TRIPPED"``), JSON key ``plc_state``.
    """

    ok: bool
    watchdog_tripped: bool | None = None
    ready: bool | None = None
    estop: bool | None = None
    error: str | None = None
    state: str | None = None

    def to_json(self) -> dict[str, object]:
        record: dict[str, object]
        if not self.ok:
            record = {"heartbeat": False, "error": self.error}
            if self.watchdog_tripped:
                record["watchdog_tripped"] = True
        else:
            record = {"heartbeat": True, "watchdog_tripped": self.watchdog_tripped, "ready": self.ready,
                      "estop": self.estop}
        if self.state is not None:
            record["plc_state"] = self.state
        return record
