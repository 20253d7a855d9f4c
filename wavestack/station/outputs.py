"""What the station sends to the polishing PLC: removal commands through the safety stage, and a heartbeat.

Every valid result becomes a removal request (``gain x`` the measured surface per Zernike term);
the :class:`~wavestack.drivers.safety.SafetyStage` clips it to the drive limits, limits its change
per update, and holds the last safe command on an invalid or stale result. Only what the stage
forwards is sent. The heartbeat is sent from the result loop, so it stops when the pipeline stalls
and the PLC's watchdog sees a dead host. A PLC error never stops the station: it is reported with
the result, and the next cycle tries again.

The output is *armed* by the first valid, fresh result. Until then results are held by the output
itself, at INFO level (:func:`start_up_hold` says why): on a normal start the first result is stale
because the first aperture detection and fitter take over a second (1.26 s measured on the default
station), and holding it is right but no fault. From the first fresh result on, every result
passes the safety stage, whose WARNING on a stale or invalid result is then a real fault; a lost
device always goes to the stage, armed or not.
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
from wavestack.pipeline import wavefront_to_surface, waves_to_nm

logger = logging.getLogger(__name__)

_MAX_COMMAND_ID = 0xFFFF


def start_up_hold(*, valid: bool, has_request: bool, age_s: float, max_age_s: float) -> tuple[str, str] | None:
    """Why a result is held while the output is not armed yet, or None when it arms the output (pure).

    Parameters
    ----------
    valid : bool
        The result is valid.
    has_request : bool
        It carries coefficients.
    age_s : float
        From the measurement to now, s.
    max_age_s : float
        The safety stage's limit on ``age_s``.

    Returns
    -------
    (status, reason) or None
        ``status`` in the safety stage's words (``"INVALID|HELD|NOT_ARMED"``, ``"STALE|HELD|NOT_ARMED"``)
        and why; None for a valid result with coefficients measured at most ``max_age_s`` ago.

    Examples
    --------
    >>> start_up_hold(valid=True, has_request=True, age_s=1.3, max_age_s=1.0)
    ('STALE|HELD|NOT_ARMED', 'output not armed yet: first result measured 1.3 s ago, max_age_s=1')
    >>> start_up_hold(valid=True, has_request=True, age_s=0.05, max_age_s=1.0) is None
    True
    """
    flags, reasons = [], []
    if not (valid and has_request):
        flags.append("INVALID")
        reasons.append("result invalid")
    if not age_s <= max_age_s:  # NaN is not fresh either
        flags.append("STALE")
        reasons.append(f"first result measured {age_s:.3g} s ago, max_age_s={max_age_s:g}")
    if not flags:
        return None
    return "|".join([*flags, "HELD", "NOT_ARMED"]), "output not armed yet: " + "; ".join(reasons)


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
    heartbeat_period_s : float
        Longest gap between heartbeats while the loop waits on a device (see :meth:`keep_alive`).
    """

    def __init__(self, link: PolishingLink, settings: OutputSettings, n_terms: int, *, wavelength_nm: float,
                 max_age_s: float, timeout_s: float, heartbeat_period_s: float = 0.5) -> None:
        self._heartbeat_period_s = heartbeat_period_s
        self._last_heartbeat_s = -float("inf")
        self._link = link
        self._settings = settings
        self._n_terms = n_terms
        # removal (surface nm) per wave of measured wavefront
        self._scale_nm = wavefront_to_surface(waves_to_nm(1.0, wavelength_nm), settings.surface_factor) * settings.gain
        self._timeout_s = timeout_s
        self._command_id = 0
        self._max_age_s = max_age_s
        self._heartbeat_started = False
        self._output_armed = False  # by the first valid fresh result (see the module notes)
        self._hold_logged = False
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
            if not self._heartbeat_started and self._command_id == 0 \
                    and self._link.read_status(self._timeout_s).watchdog_tripped:
                logger.info("PLC watchdog tripped during start-up (before any command); re-arming it once")
                self._link.rearm(self._timeout_s)
            self._heartbeat_started = True
            self._last_heartbeat_s = time.monotonic()
            status = self._link.heartbeat(self._timeout_s)
        except DeviceError as error:
            logger.warning("PLC heartbeat failed: %s", error)
            return Heartbeat(False, error=str(error))
        return Heartbeat(True, watchdog_tripped=status.watchdog_tripped, ready=status.ready, estop=status.estop)

    def keep_alive(self, now_s: float) -> Heartbeat | None:
        """A heartbeat (never a command) when ``heartbeat_period_s`` has passed since the last one, else None.

        ``now_s`` is ``time.monotonic()``.
        """
        if now_s - self._last_heartbeat_s < self._heartbeat_period_s:
            return None
        return self.heartbeat()

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
        """No measurement this cycle (a lost device): the safety stage holds (a fault, armed or not); no heartbeat."""
        now_s = now_ns * 1e-9
        return OutputRecord(None, self._through_stage(None, valid=False, measured_at_s=now_s, now_s=now_s,
                                                      reason=reason))

    def publish(self, coefficients_waves: NDArray[np.float64] | None, *, valid: bool, measured_at_s: float,
                now_s: float, reason: str | None) -> SentCommand:
        """Pass one result through the safety stage and send what it forwards.

        Until the first valid fresh result arms the output, a result that would not arm it is held
        here, without the stage, and logged at INFO once (see :func:`start_up_hold`).

        Returns
        -------
        SentCommand
            ``sent``, ``command_id`` (or None), ``status`` (the safety flags, e.g.
            ``"CLIPPED|RATE_LIMITED"`` or ``"STALE|HELD"``; ``"...|HELD|NOT_ARMED"`` before arming),
            ``reason`` and ``values_nm``.
        """
        if not self._output_armed:
            hold = start_up_hold(valid=valid, has_request=coefficients_waves is not None,
                                 age_s=now_s - measured_at_s, max_age_s=self._max_age_s)
            if hold is not None:
                status, why = hold
                logger.log(logging.DEBUG if self._hold_logged else logging.INFO, "PLC output held: %s", why)
                self._hold_logged = True
                return SentCommand(sent=False, command_id=None, status=status, reason=why,
                                   values_nm=tuple(float(v) for v in self.stage.last_output))
            self._output_armed = True
            logger.info("PLC output armed by the first valid fresh result")
        return self._through_stage(coefficients_waves, valid=valid, measured_at_s=measured_at_s, now_s=now_s,
                                   reason=reason)

    def _through_stage(self, coefficients_waves: NDArray[np.float64] | None, *, valid: bool, measured_at_s: float,
                       now_s: float, reason: str | None) -> SentCommand:
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
