"""The PLC output's life as a state machine in data: a frozen state and a pure transition function.

The output (:class:`~wavestack.station.outputs.PlcOutput`) sends a removal command only in
``ARMED``. What it observes of the PLC at each heartbeat, and what the loop brings, are events:

=================  ============================================================================
event              meaning
=================  ============================================================================
``HEALTHY``        heartbeat echoed, PLC ready (watchdog running, no e-stop, not busy)
``BUSY``           heartbeat echoed, PLC running a command (scanning, but takes none now)
``TRIPPED``        the watchdog has tripped (exception 4): outputs zeroed until re-armed
``ESTOP``          the emergency stop is pressed
``NOT_SCANNING``   the PLC answers but its logic no longer echoes the heartbeat
``NOT_READY``      scanning but not ready for another reason
``LINK_DOWN``      no usable reply (timeout, lost connection, malformed reply)
``ARMING_RESULT``  a valid, fresh result, and the machine's outputs were read back
``ACCEPTED``       the PLC acknowledged a command
=================  ============================================================================

Rules (every state x event pair is tested in ``tests/station/test_output_state.py``):

- A fault event (``TRIPPED``, ``ESTOP``, ``NOT_SCANNING``, ``NOT_READY``, ``LINK_DOWN``) moves any
  state to the fault's mode: nothing is sent from there.
- ``HEALTHY`` or ``BUSY`` after a fault moves to ``NOT_ARMED``: the PLC is usable again, but the
  output re-arms only on the next ``ARMING_RESULT``, i.e. after reading back what the machine holds
  (a trip zeroes the outputs), so the rate limit counts from the machine's real state.
- Recovery from ``TRIPPED`` is never the station's doing: the PLC reports healthy only after an
  operator re-armed it (``wavestack plc rearm``, see the README). The one exception, kept from
  before: a watchdog that tripped before any command was ever accepted (a slow first result) is
  re-armed once by the station (action ``REARM_AT_START_UP``), and that is logged.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

__all__ = ["OutputAction", "OutputMode", "OutputState", "PlcEvent", "hold_reason", "transition"]


class OutputMode(enum.Enum):
    """Where the output is; only ``ARMED`` sends commands."""

    NOT_ARMED = "not armed"
    ARMED = "armed"
    TRIPPED = "tripped"
    ESTOP = "e-stop"
    NOT_SCANNING = "not scanning"
    NOT_READY = "not ready"
    LINK_DOWN = "link down"


class PlcEvent(enum.Enum):
    """What the output observed (see the module table)."""

    HEALTHY = "healthy"
    BUSY = "busy"
    TRIPPED = "tripped"
    ESTOP = "e-stop"
    NOT_SCANNING = "not scanning"
    NOT_READY = "not ready"
    LINK_DOWN = "link down"
    ARMING_RESULT = "arming result"
    ACCEPTED = "accepted"


class OutputAction(enum.Enum):
    """What the output must do after a transition."""

    NONE = "none"
    REARM_AT_START_UP = "re-arm at start-up"


_FAULT_MODES = {
    PlcEvent.TRIPPED: OutputMode.TRIPPED,
    PlcEvent.ESTOP: OutputMode.ESTOP,
    PlcEvent.NOT_SCANNING: OutputMode.NOT_SCANNING,
    PlcEvent.NOT_READY: OutputMode.NOT_READY,
    PlcEvent.LINK_DOWN: OutputMode.LINK_DOWN,
}

_HOLD_REASONS = {
    OutputMode.NOT_ARMED: "output not armed: waiting for a valid fresh result",
    OutputMode.ARMED: "",
    OutputMode.TRIPPED: "PLC watchdog tripped (outputs zeroed): nothing is sent until an operator re-arms it "
                        "with `wavestack plc rearm`",
    OutputMode.ESTOP: "PLC emergency stop pressed: nothing is sent until it is released",
    OutputMode.NOT_SCANNING: "PLC program not scanning (heartbeat echo stale): nothing is sent until it echoes again",
    OutputMode.NOT_READY: "PLC not ready: nothing is sent until it is",
    OutputMode.LINK_DOWN: "PLC link down: nothing is sent until the PLC answers again",
}


@dataclass(frozen=True)
class OutputState:
    """The output's state.

    Attributes
    ----------
    mode : OutputMode
    start_up_rearm : bool
        The one start-up re-arm is still allowed: no command accepted yet and not used.
    """

    mode: OutputMode = OutputMode.NOT_ARMED
    start_up_rearm: bool = True

    @property
    def may_send(self) -> bool:
        """Commands go out only when armed."""
        return self.mode is OutputMode.ARMED


def hold_reason(mode: OutputMode) -> str:
    """Why nothing is sent in ``mode`` (empty for ``ARMED``)."""
    return _HOLD_REASONS[mode]


def transition(state: OutputState, event: PlcEvent) -> tuple[OutputState, OutputAction]:
    """The next state and the action after ``event`` (pure; see the module rules).

    Examples
    --------
    >>> s, a = transition(OutputState(OutputMode.ARMED, False), PlcEvent.TRIPPED)
    >>> s.mode.name, a.name
    ('TRIPPED', 'NONE')
    >>> transition(s, PlcEvent.ARMING_RESULT)[0].mode.name  # a result does not recover a trip
    'TRIPPED'
    >>> transition(s, PlcEvent.HEALTHY)[0].mode.name  # re-armed by the operator: arm again later
    'NOT_ARMED'
    """
    mode = state.mode
    if event in _FAULT_MODES:
        if event is PlcEvent.TRIPPED and state.start_up_rearm and mode is OutputMode.NOT_ARMED:
            return replace(state, start_up_rearm=False), OutputAction.REARM_AT_START_UP
        return replace(state, mode=_FAULT_MODES[event]), OutputAction.NONE
    if event in (PlcEvent.HEALTHY, PlcEvent.BUSY):
        if mode in (OutputMode.NOT_ARMED, OutputMode.ARMED):
            return state, OutputAction.NONE
        return replace(state, mode=OutputMode.NOT_ARMED), OutputAction.NONE
    if event is PlcEvent.ARMING_RESULT:
        if mode is OutputMode.NOT_ARMED:
            return replace(state, mode=OutputMode.ARMED), OutputAction.NONE
        return state, OutputAction.NONE
    assert event is PlcEvent.ACCEPTED
    return replace(state, start_up_rearm=False), OutputAction.NONE
