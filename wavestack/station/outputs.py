"""What the station sends to the polishing PLC: removal commands through the safety stage, and a heartbeat.

Every valid result becomes a removal request (``gain x`` the measured surface per Zernike term);
the :class:`~wavestack.drivers.safety.SafetyStage` clips it to the drive limits, limits its change
per update, and holds the last safe command on an invalid or stale result. Only what the stage
proposes is sent, and only what the PLC acknowledged is committed to the stage: a refused or lost
command never moves the base of the rate limit. The link itself checks the same limits before the
wire (:class:`~wavestack.drivers.plc.CommandLimits`, set here with ``restrict``) and settles a
command whose reply was lost before sending another.

The heartbeat is sent from the result loop (each result, each lost-device cycle, and
:meth:`PlcOutput.keep_alive` between slices of the loop's waits for frames), so it stops only when
the host itself stalls: a camera or piezo fault is not a host fault. A PLC error never stops the
station: it is reported with the result, and the next cycle tries again.

Every cycle also shows its result on the machine's panel: the PLC's display block (valid, residual
RMS, PVr, the drawing's verdict and limiting quantity; :mod:`.plc_display`), written through the same
owning link after the command, whatever the command's fate (a held or invalid result is shown as
it is). A failed display write is reported with the result and never holds a command back.

The output's life is the state machine of :mod:`wavestack.station.output_state`: commands go out
only while ``ARMED``; a tripped, e-stopped, not scanning, not ready or unreachable PLC gets none;
when it is healthy again (a trip: after an operator's ``wavestack plc rearm``) the output reads
back what the machine holds, resets the safety stage to it and re-arms on a valid fresh result.

The output is *armed* by the first valid, fresh result. Until then results are held by the output
itself, at INFO level (:func:`start_up_hold` says why): on a normal start the first result is stale
because the first aperture detection and fitter take over a second (1.26 s measured on the default
station), and holding it is right but no fault. From the first fresh result on, every result
passes the safety stage, whose WARNING on a stale or invalid result is then a real fault; a lost
device always goes to the stage, armed or not (and is held).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.config import OutputSettings
from wavestack.drivers.errors import DeviceError
from wavestack.drivers.plc import (CommandLimits, HeartbeatEchoStale, PlcRefused, PlcStatus, PolishingLink, ResultDisplay,
                                   invalid_display)
from wavestack.drivers.safety import SafeOutput, SafetyLimits, SafetyStage
from wavestack.station.output_state import OutputAction, OutputMode, OutputState, PlcEvent, hold_reason, transition
from wavestack.station.plc_display import result_display
from wavestack.station.plc_status import Heartbeat
from wavestack.station.results import OutputRecord, SentCommand, StationResult

logger = logging.getLogger(__name__)

_WATCHDOG_EXCEPTION = 4


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
        Connected, self-check passed. Its command limits are tightened to ``settings``.
    settings : OutputSettings
    n_terms : int
        Terms in the PLC's command block (Noll 1..n_terms).
    wavelength_nm : float
    max_age_s : float
        A result measured longer ago than this is stale and never forwarded.
    timeout_s : float
        Budget of each PLC exchange.
    heartbeat_period_s : float
        :meth:`keep_alive` beats when the last heartbeat is at least this old, s (the station passes
        a quarter of the PLC's watchdog timeout).
    spec_configured : bool
        The station checks a drawing tolerance (the display shows a result without a verdict as
        "not judged"). Results go to the display block only when the link's map has one.
    surface_factor : float or None
        Surface per wavefront of the display's residual RMS: the surface figures' (``[surface]``),
        so that it shares PVr's convention; None: the output's (``[outputs] surface_factor``).

    Notes
    -----
    One owner (the station's loop) calls it; a lock makes the calls atomic anyway.
    """

    def __init__(self, link: PolishingLink, settings: OutputSettings, n_terms: int, *, wavelength_nm: float,
                 max_age_s: float, timeout_s: float, heartbeat_period_s: float = 0.5,
                 spec_configured: bool = False, surface_factor: float | None = None) -> None:
        if not heartbeat_period_s > 0:
            raise ValueError(f"heartbeat_period_s must be > 0 s, got {heartbeat_period_s!r}")
        self._link = link
        self._settings = settings
        self._n_terms = n_terms
        # surface nm per wave of measured wavefront: waves x wavelength_nm is the wavefront in nm, x surface_factor
        # the surface (docs/conventions.md, "Surface")
        self._scale_nm = wavelength_nm * settings.surface_factor * settings.gain
        self._surface_nm_per_wave = wavelength_nm * (settings.surface_factor if surface_factor is None else surface_factor)
        self._spec_configured = spec_configured
        self._shows_results = link.register_map.display is not None
        self._display_failing = False
        self._timeout_s = timeout_s
        self._max_age_s = max_age_s
        self._heartbeat_period_s = float(heartbeat_period_s)
        self._last_beat_s = -math.inf
        self._lock = threading.RLock()
        self._state = OutputState()
        self._fault_detail: str | None = None
        self._unsettled = False  # a send failed: the stage must learn what the machine holds first
        self._hold_logged = False
        link.restrict(CommandLimits(settings.max_removal_nm, settings.max_step_nm))
        self.stage = SafetyStage(SafetyLimits(
            lower=np.full(n_terms, -settings.max_removal_nm), upper=np.full(n_terms, settings.max_removal_nm),
            max_step=np.full(n_terms, settings.max_step_nm), max_age_s=max_age_s, invalid_action="hold",
            safe_value=np.zeros(n_terms)))

    @property
    def state(self) -> OutputState:
        """Where the output's state machine is."""
        return self._state

    def requested_removal_nm(self, coefficients_waves: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        """The removal per PLC term before the safety stage (None when there are no coefficients)."""
        if coefficients_waves is None:
            return None
        removal = np.zeros(self._n_terms)
        count = min(self._n_terms, len(coefficients_waves))
        removal[:count] = np.asarray(coefficients_waves[:count], dtype=np.float64) * self._scale_nm
        removal[: self._settings.first_term - 1] = 0.0  # piston and tilts are alignment, not polishing
        return removal

    # ------------------------------------------------------------------ heartbeat
    def heartbeat(self) -> Heartbeat:
        """One heartbeat; returns the PLC status (or the error) for the result record.

        The observed status drives the state machine. The PLC's watchdog starts counting at the
        connection's first heartbeat, and the station's first result can take longer than the
        watchdog allows: a watchdog that tripped *before any command was accepted* is re-armed once
        and logged; after that a trip is final until an operator re-arms it (``wavestack plc
        rearm``): a stalled host must not re-arm its own watchdog.
        """
        with self._lock:
            beat, event = self._beat_once()
            if self._observe(event) is OutputAction.REARM_AT_START_UP:
                logger.info("PLC watchdog tripped during start-up (before any command); re-arming it once")
                try:
                    self._link.rearm(self._timeout_s)
                except DeviceError as error:
                    logger.warning("PLC start-up re-arm failed: %s", error)
                beat, event = self._beat_once()
                self._observe(event)
            return replace(beat, state=self._state.mode.name)

    def keep_alive(self, now_s: float) -> Heartbeat | None:
        """A heartbeat (never a command) if the last one is at least ``heartbeat_period_s`` old, else None.

        Parameters
        ----------
        now_s : float
            ``time.monotonic()``, s: the loop calls this between slices of its waits for frames.
        """
        with self._lock:
            if now_s - self._last_beat_s < self._heartbeat_period_s:
                return None
            return self.heartbeat()

    def _beat_once(self) -> tuple[Heartbeat, PlcEvent]:
        self._last_beat_s = time.monotonic()
        try:
            status = self._link.heartbeat(self._timeout_s)
        except HeartbeatEchoStale as error:
            self._fault_detail = str(error)
            return Heartbeat(False, error=str(error)), PlcEvent.NOT_SCANNING
        except PlcRefused as error:  # the heartbeat write is refused (4) only by a tripped watchdog
            self._fault_detail = str(error)
            tripped = error.exception_code == _WATCHDOG_EXCEPTION
            return (Heartbeat(False, watchdog_tripped=tripped or None, error=str(error)),
                    PlcEvent.TRIPPED if tripped else PlcEvent.LINK_DOWN)
        except DeviceError as error:
            logger.warning("PLC heartbeat failed: %s", error)
            self._fault_detail = str(error)
            return Heartbeat(False, error=str(error)), PlcEvent.LINK_DOWN
        event = _event_of(status)
        self._fault_detail = None if event in (PlcEvent.HEALTHY, PlcEvent.BUSY) else f"PLC status word {status.raw_word}"
        return Heartbeat(True, watchdog_tripped=status.watchdog_tripped, ready=status.ready, estop=status.estop), event

    def _observe(self, event: PlcEvent) -> OutputAction:
        before = self._state
        self._state, action = transition(before, event)
        if self._state.mode is not before.mode:
            level = logging.INFO if self._state.mode in (OutputMode.ARMED, OutputMode.NOT_ARMED) else logging.WARNING
            logger.log(level, "PLC output %s -> %s (%s)", before.mode.value, self._state.mode.value, event.value)
        return action

    # ------------------------------------------------------------------ results
    def send(self, result: StationResult) -> OutputRecord:
        """The cycle's heartbeat, the result through the safety stage to the PLC, then the result on its panel.

        Returns
        -------
        OutputRecord
            The heartbeat's status, what the safety stage made of the result, and whether the
            display block took it.
        """
        with self._lock:
            heartbeat = self.heartbeat()
            coefficients = np.asarray(result.coefficients, dtype=np.float64) if result.coefficients else None
            command = self.publish(coefficients, valid=result.valid, measured_at_s=result.exposure_time_ns * 1e-9,
                                   now_s=time.time_ns() * 1e-9, reason=result.reason)
            display = result_display(result, surface_nm_per_wave=self._surface_nm_per_wave,
                                     spec_configured=self._spec_configured)
            return OutputRecord(heartbeat, command, self._show(display, heartbeat))

    def device_lost(self, reason: str, now_ns: int, index: int) -> OutputRecord:
        """No measurement this cycle (a lost device): a heartbeat (the host is alive), the stage holds,
        and the panel shows result ``index`` invalid."""
        now_s = now_ns * 1e-9
        with self._lock:
            heartbeat = self.heartbeat()
            safe = self.stage.propose(None, valid=False, measured_at_s=now_s, now_s=now_s, reason=reason)
            shown = self._show(invalid_display(index, has_spec=self._spec_configured), heartbeat)
            return OutputRecord(heartbeat, self._held(safe), shown)

    def _show(self, display: ResultDisplay, heartbeat: Heartbeat) -> bool | None:
        """Write ``display`` to the panel; None without a display block, False when not written (the
        heartbeat failed, so the PLC takes no write from this host now, or the write failed)."""
        if not self._shows_results:
            return None
        if not heartbeat.ok:
            return False
        try:
            self._link.show_result(display, self._timeout_s)
        except DeviceError as error:
            level = logging.DEBUG if self._display_failing else logging.WARNING  # once per run of failures
            logger.log(level, "PLC display block not written (result %d): %s", display.result_index, error)
            self._display_failing = True
            return False
        self._display_failing = False
        return True

    def publish(self, coefficients_waves: NDArray[np.float64] | None, *, valid: bool, measured_at_s: float,
                now_s: float, reason: str | None) -> SentCommand:
        """Pass one result through the safety stage and send what it proposes, if the output is armed.

        Until a valid fresh result arms the output, a result that would not arm it is held here,
        without the stage, and logged at INFO once (see :func:`start_up_hold`). Arming reads back
        what the machine holds and resets the stage to it. In a fault mode (tripped, e-stop, not
        scanning, not ready, link down) every result is held with the mode's reason.

        Returns
        -------
        SentCommand
            ``sent``, ``command_id`` (or None), ``status`` (the safety flags, e.g.
            ``"CLIPPED|RATE_LIMITED"`` or ``"STALE|HELD"``; ``"...|HELD|NOT_ARMED"`` before arming;
            ``"HELD|TRIPPED"`` and the like in a fault mode; ``"...|NOT_SENT"`` when the PLC did not
            take it; ``"HELD|UNRESOLVED"`` while the outcome of a failed send cannot be told),
            ``reason`` and ``values_nm`` (what the machine holds unless sent).
        """
        with self._lock:
            mode = self._state.mode
            if mode is OutputMode.NOT_ARMED:
                held = self._arm(valid, coefficients_waves is not None, now_s - measured_at_s)
                if held is not None:
                    return held
            elif mode is not OutputMode.ARMED:
                detail = f" ({self._fault_detail})" if self._fault_detail else ""
                return SentCommand(sent=False, command_id=None, status=f"HELD|{mode.name}",
                                   reason=hold_reason(mode) + detail, values_nm=_values(self.stage.last_output))
            unresolved = self._settle()
            if unresolved is not None:
                return unresolved
            safe = self.stage.propose(self.requested_removal_nm(coefficients_waves), valid=valid,
                                      measured_at_s=measured_at_s, now_s=now_s, reason=reason)
            if not safe.forwarded or not self._settings.enabled:
                return self._held(safe)
            return self._send(safe)

    def _arm(self, valid: bool, has_request: bool, age_s: float) -> SentCommand | None:
        """Arm on a valid fresh result (reading back what the machine holds); else the held record."""
        hold = start_up_hold(valid=valid, has_request=has_request, age_s=age_s, max_age_s=self._max_age_s)
        why: str | None = None
        if hold is None:
            try:
                self.stage.reset(self._link.read_outputs(self._timeout_s).setpoint_nm)
            except (DeviceError, ValueError) as error:
                why = f"output not armed: reading back the machine's outputs failed: {error}"
            else:
                self._unsettled = False  # the stage starts from the machine's read-back
                self._observe(PlcEvent.ARMING_RESULT)
                logger.info("PLC output armed by a valid fresh result (the machine holds %s nm)",
                            self.stage.last_output.tolist())
                return None
        status, why = hold if hold is not None else ("HELD|NOT_ARMED", why)
        logger.log(logging.DEBUG if self._hold_logged else logging.INFO, "PLC output held: %s", why)
        self._hold_logged = True
        return SentCommand(sent=False, command_id=None, status=status, reason=why,
                           values_nm=_values(self.stage.last_output))

    def _settle(self) -> SentCommand | None:
        """After a failed send: reset the stage to what the machine holds (the link settles a lost command
        from the PLC's last accepted id); if that cannot be told, the held record (nothing is sent)."""
        if not self._unsettled:
            return None
        try:
            self.stage.reset(self._link.held_removal(self._timeout_s))
        except (DeviceError, ValueError) as error:
            return SentCommand(sent=False, command_id=None, status="HELD|UNRESOLVED",
                               reason=f"PLC: the last command's outcome is unknown, nothing is sent: {error}",
                               values_nm=_values(self.stage.last_output))
        self._unsettled = False
        return None

    def _held(self, safe: SafeOutput) -> SentCommand:
        return SentCommand(sent=False, command_id=None, status=_flags(safe.status), reason=safe.reason,
                           values_nm=_values(safe.values))

    def _send(self, safe: SafeOutput) -> SentCommand:
        """Send a proposal; commit it to the stage only once the PLC acknowledged it."""
        command_id = self._link.next_command_id()
        try:
            self._link.send_removal(command_id, safe.values, self._settings.passes, self._timeout_s)
        except DeviceError as error:
            logger.warning("PLC command %d not taken: %s", command_id, error)
            self._unsettled = True
            return SentCommand(sent=False, command_id=None, status=f"{_flags(safe.status)}|NOT_SENT",
                               reason=f"PLC: {error}", values_nm=_values(self.stage.last_output))
        self.stage.commit(safe.values)
        self._observe(PlcEvent.ACCEPTED)
        return SentCommand(sent=True, command_id=command_id, status=_flags(safe.status), reason=safe.reason,
                           values_nm=_values(safe.values))


def _event_of(status: PlcStatus) -> PlcEvent:
    """The state-machine event a heartbeat's status stands for."""
    if status.watchdog_tripped:
        return PlcEvent.TRIPPED
    if status.estop:
        return PlcEvent.ESTOP
    if status.busy:
        return PlcEvent.BUSY
    return PlcEvent.HEALTHY if status.ready else PlcEvent.NOT_READY


def _values(values: NDArray[np.float64]) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def _flags(status: Any) -> str:
    names = [flag.name for flag in type(status) if flag.name and flag.value and flag in status]
    return "|".join(names) if names else "OK"
