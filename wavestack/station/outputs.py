"""What the station sends to the polishing PLC: removal commands through the safety stage, and a heartbeat.

Every valid result becomes a removal request (``gain x`` the measured surface per Zernike term);
the :class:`~wavestack.drivers.safety.SafetyStage` clips it to the drive limits, limits its change
per update, and holds the last safe command on an invalid or stale result. Only what the stage
forwards is sent. The heartbeat is sent from the result loop, so it stops when the pipeline stalls
and the PLC's watchdog sees a dead host. A PLC error never stops the station: it is reported with
the result, and the next cycle tries again.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.errors import DeviceError
from wavestack.drivers.plc import PolishingLink
from wavestack.drivers.safety import SafetyLimits, SafetyStage
from wavestack.config import OutputSettings
from wavestack.station.results import Heartbeat, OutputRecord, SentCommand, StationResult

logger = logging.getLogger(__name__)

_MAX_COMMAND_ID = 0xFFFF


class PlcOutput:
    """Turns results into safe removal commands on a :class:`PolishingLink`.

    Parameters
    ----------
    link : PolishingLink
        Connected, self-check passed.
    settings : OutputSettings
    n_terms : int
        Terms in the PLC's command block (Noll 1..n_terms).
    wavelength_nm : float
    max_age_s : float
        A result measured longer ago than this is stale and never forwarded.
    timeout_s : float
        Budget of each PLC exchange.
    """

    def __init__(self, link: PolishingLink, settings: OutputSettings, n_terms: int, *, wavelength_nm: float,
                 max_age_s: float, timeout_s: float) -> None:
        self._link = link
        self._settings = settings
        self._n_terms = n_terms
        self._scale_nm = wavelength_nm * settings.surface_factor * settings.gain
        self._timeout_s = timeout_s
        self._command_id = 0
        self._armed = False
        self.stage = SafetyStage(SafetyLimits(
            lower=np.full(n_terms, -settings.max_removal_nm), upper=np.full(n_terms, settings.max_removal_nm),
            max_step=np.full(n_terms, settings.max_step_nm), max_age_s=max_age_s, invalid_action="hold",
            safe_value=np.zeros(n_terms)))

    def requested_removal_nm(self, coefficients_waves: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        """The removal per PLC term before the safety stage (None when there are no coefficients)."""
        if coefficients_waves is None:
            return None
        removal = np.zeros(self._n_terms)
        count = min(self._n_terms, len(coefficients_waves))
        removal[:count] = np.asarray(coefficients_waves[:count], dtype=np.float64) * self._scale_nm
        removal[: self._settings.first_term - 1] = 0.0  # piston and tilts are alignment, not polishing
        return removal

    def heartbeat(self) -> Heartbeat:
        """One heartbeat; returns the PLC status (or the error) for the result record.

        The PLC's watchdog starts counting at the connection's first heartbeat, and the station's
        first result (first aperture, first fitter, first spatial unwrap) can take longer than
        the watchdog allows. A watchdog that tripped *before the first command was ever sent* is
        therefore re-armed once, at the first result, and logged; after that a trip is final
        for this run (a stalled host must not re-arm its own watchdog) and the results carry it.
        """
        try:
            if not self._armed and self._command_id == 0 and self._link.read_status(self._timeout_s).watchdog_tripped:
                logger.info("PLC watchdog tripped during start-up (before any command); re-arming it once")
                self._link.rearm(self._timeout_s)
            self._armed = True
            status = self._link.heartbeat(self._timeout_s)
        except DeviceError as error:
            logger.warning("PLC heartbeat failed: %s", error)
            return Heartbeat(False, error=str(error))
        return Heartbeat(True, watchdog_tripped=status.watchdog_tripped, ready=status.ready, estop=status.estop)

    def send(self, result: StationResult) -> OutputRecord:
        """The cycle's heartbeat, then the result through the safety stage to the PLC.

        Returns
        -------
        OutputRecord
            The heartbeat's status and what the safety stage made of the result.
        """
        heartbeat = self.heartbeat()
        coefficients = np.asarray(result.coefficients, dtype=np.float64) if result.coefficients else None
        command = self.publish(coefficients, valid=result.valid, measured_at_s=result.exposure_time_ns * 1e-9,
                               now_s=time.time_ns() * 1e-9, reason=result.reason)
        return OutputRecord(heartbeat, command)

    def device_lost(self, reason: str, now_ns: int) -> OutputRecord:
        """No measurement this cycle (a lost device): the safety stage holds; no heartbeat."""
        now_s = now_ns * 1e-9
        return OutputRecord(None, self.publish(None, valid=False, measured_at_s=now_s, now_s=now_s, reason=reason))

    def publish(self, coefficients_waves: NDArray[np.float64] | None, *, valid: bool, measured_at_s: float,
                now_s: float, reason: str | None) -> SentCommand:
        """Pass one result through the safety stage and send what it forwards.

        Returns
        -------
        SentCommand
            ``sent``, ``command_id`` (or None), ``status`` (the safety flags, e.g.
            ``"CLIPPED|RATE_LIMITED"`` or ``"HELD|STALE"``), ``reason`` and ``values_nm``.
        """
        safe = self.stage.update(self.requested_removal_nm(coefficients_waves), valid=valid,
                                 measured_at_s=measured_at_s, now_s=now_s, reason=reason)
        held = SentCommand(sent=False, command_id=None, status=_flags(safe.status), reason=safe.reason,
                           values_nm=tuple(float(v) for v in safe.values))
        if not safe.forwarded or not self._settings.enabled:
            return held
        command_id = self._command_id % _MAX_COMMAND_ID + 1
        try:
            self._link.send_removal(command_id, safe.values, self._settings.passes, self._timeout_s)
        except DeviceError as error:
            logger.warning("PLC command %d not sent: %s", command_id, error)
            return replace(held, reason=f"PLC: {error}")
        self._command_id = command_id
        return replace(held, sent=True, command_id=command_id)


def _flags(status: Any) -> str:
    names = [flag.name for flag in type(status) if flag.name and flag.value and flag in status]
    return "|".join(names) if names else "OK"
