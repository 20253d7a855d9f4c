"""What the link knows about the machine's removal command: limits, the held command, an unresolved one.

Pure values and bookkeeping (no I/O), used by :class:`~wavestack.drivers.plc.driver.PolishingLink`:

- :class:`CommandLimits`: the largest ``|removal|`` per term and the largest change from the command
  the machine holds. The link checks every command against them *before the wire*, so no caller
  holding a link (the station's output, a script, a later polishing loop) can skip them; the
  station's :class:`~wavestack.drivers.safety.SafetyStage` stays in front for hold, staleness and
  rate shaping, and never proposes what the link would refuse.
- :class:`CommandLedger`: the command the machine holds (confirmed by the PLC's last accepted id,
  or read back from its output block) and a command whose fate is unknown (written, but the reply
  was lost). The link resolves an unknown fate from the PLC's status before it sends anything else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.drivers.errors import LimitError

__all__ = ["CommandLedger", "CommandLimits", "CommandRefused", "PendingCommand"]

_MAX_ID = 0xFFFF


class CommandRefused(LimitError):
    """A removal command outside the link's :class:`CommandLimits`; nothing was sent."""


@dataclass(frozen=True)
class CommandLimits:
    """Limits every removal command must meet before it reaches the wire.

    Attributes
    ----------
    max_removal_nm
        Largest ``|removal|`` per term, nm (``>= 0``).
    max_step_nm
        Largest change per term from the command the machine holds (the last acknowledged one, or
        the output block read back), nm (``> 0``). The check allows the float32 rounding of the
        held value (one float32 ulp), since the PLC holds float32.
    """

    max_removal_nm: float
    max_step_nm: float

    def __post_init__(self) -> None:
        for name, low_open in (("max_removal_nm", False), ("max_step_nm", True)):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)) or value < 0 or (low_open and value == 0):
                bound = "> 0" if low_open else ">= 0"
                raise ValueError(f"CommandLimits.{name}: expected a finite number {bound} (nm), got {value!r}")
            object.__setattr__(self, name, float(value))

    def tightened(self, other: CommandLimits | None) -> CommandLimits:
        """The stricter of ``self`` and ``other`` on each limit."""
        if other is None:
            return self
        return CommandLimits(min(self.max_removal_nm, other.max_removal_nm), min(self.max_step_nm, other.max_step_nm))

    def violation(self, values: NDArray[np.float64], held: NDArray[np.float64]) -> str | None:
        """Why ``values`` may not be sent while the machine holds ``held`` (both nm, shape (n,)), or None."""
        over = np.flatnonzero(~(np.abs(values) <= self.max_removal_nm))
        if over.size:
            return (f"removal on terms {(over + 1).tolist()} is {values[over].tolist()} nm, expected |removal| <= "
                    f"max_removal_nm {self.max_removal_nm:g}")
        tolerance = np.spacing(np.abs(held).astype(np.float32)).astype(np.float64)
        step = np.abs(values - held)
        big = np.flatnonzero(~(step <= self.max_step_nm + tolerance))
        if big.size:
            return (f"step on terms {(big + 1).tolist()} is {step[big].tolist()} nm from the held command "
                    f"{held[big].tolist()} nm, expected <= max_step_nm {self.max_step_nm:g}")
        return None


@dataclass(frozen=True)
class PendingCommand:
    """A command written (or being written) whose acknowledge has not been seen."""

    command_id: int
    values_nm: NDArray[np.float64]


def as_float32(values: ArrayLike) -> NDArray[np.float64]:
    """``values`` as the PLC holds them (float32), returned as a read-only float64 array."""
    held = np.asarray(values, dtype=np.float64).astype(np.float32).astype(np.float64)
    held.setflags(write=False)
    return held


class CommandLedger:
    """The machine's command as far as the host knows it (not thread-safe: the link's lock guards it).

    Attributes
    ----------
    held_id
        Id the held values belong to, or None when unknown (then :meth:`needs_read_back`).
    held_nm
        Removal per term the machine holds (float32 values), or None when unknown.
    pending
        A command written without a confirmed outcome, or None.
    last_id
        The newest id used or seen accepted (ids count on from it).
    plc_accepted
        The PLC's last accepted id at the last status read (None before one).
    """

    def __init__(self) -> None:
        self.held_id: int | None = None
        self.held_nm: NDArray[np.float64] | None = None
        self.pending: PendingCommand | None = None
        self.last_id = 0
        self.plc_accepted: int | None = None

    def next_id(self) -> int:
        """A fresh id: after every id used, never 0 and never the PLC's last accepted id (it would ignore it)."""
        candidate = self.last_id % _MAX_ID + 1
        if candidate == self.plc_accepted:
            candidate = candidate % _MAX_ID + 1
        return candidate

    def saw_accepted_id(self, accepted: int | None) -> None:
        """A status read: ids count on from the PLC's last accepted id."""
        if accepted is None:
            return
        self.plc_accepted = accepted
        if self.last_id == 0:
            self.last_id = accepted

    def invalidate(self) -> None:
        """The machine's outputs changed without a command (watchdog trip, re-arm, e-stop refusal)."""
        self.held_id = None
        self.held_nm = None

    def resolve(self, plc_last_accepted: int | None) -> str | None:
        """Settle a pending command from the PLC's last accepted id; returns what happened, or None."""
        pending, self.pending = self.pending, None
        if pending is None:
            return None
        if plc_last_accepted == pending.command_id:
            self.held_id, self.held_nm = pending.command_id, pending.values_nm
            return f"command {pending.command_id} was accepted (its reply was lost)"
        return f"command {pending.command_id} was not accepted (the PLC reports {plc_last_accepted})"

    def needs_read_back(self, plc_last_accepted: int | None) -> bool:
        """Whether the held command is unknown or the PLC accepted something else since."""
        return self.held_nm is None or self.held_id != plc_last_accepted

    def read_back(self, plc_last_accepted: int | None, setpoint_nm: ArrayLike) -> None:
        """The output block as read: the machine holds these values."""
        self.held_id, self.held_nm = plc_last_accepted, as_float32(setpoint_nm)

    def sending(self, command_id: int, values_nm: ArrayLike) -> None:
        """A command is about to be written: its fate is unknown until acknowledged or refused."""
        self.pending = PendingCommand(command_id, as_float32(values_nm))
        self.last_id = command_id

    def accepted(self) -> None:
        """The pending command was acknowledged: the machine holds it."""
        if self.pending is not None:
            self.held_id, self.held_nm = self.pending.command_id, self.pending.values_nm
        self.pending = None

    def refused(self) -> None:
        """The PLC refused the pending command (an exception reply): it never took effect."""
        self.pending = None
