"""What the PLC reports back: status word, acknowledge, machine outputs, as plain values.

Pure decoding of register contents (no I/O), so the driver's readings and the tests' ground truth
are compared as frozen dataclasses.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.plc.codec import WordOrder, decode_float32_array
from wavestack.drivers.plc.register_map import OUTPUT_HEADER_COUNT, STATUS_COUNT

__all__ = ["CommandAck", "MachineOutputs", "PlcStatus", "StatusBit", "decode_outputs", "decode_status"]


class StatusBit(enum.IntFlag):
    """Bits of the status word (status block, register 0)."""

    READY = 1 << 0  #: heartbeat live, watchdog armed, no fault, no e-stop, not busy
    BUSY = 1 << 1  #: a polishing command is running
    FAULT = 1 << 2  #: the last command was refused, or the e-stop is pressed
    ESTOP = 1 << 3  #: emergency stop pressed
    HEARTBEAT_SEEN = 1 << 4  #: the watchdog has seen the heartbeat change since start-up or re-arm


_KNOWN_BITS = sum(int(bit) for bit in StatusBit)


@dataclass(frozen=True)
class PlcStatus:
    """The PLC's state as last read.

    Attributes
    ----------
    ready, busy, fault, estop, heartbeat_seen
        The status word's bits (:class:`StatusBit`).
    watchdog_tripped
        The PLC answered exception 4 (server device failure) to the status read: its watchdog has
        tripped, outputs are zero and every request is refused until :meth:`rearm`. The other
        fields are then unknown and reported fail-safe (not ready, fault set, ids None).
    last_accepted_id
        Id of the last command the PLC accepted (0 = none yet), None when unknown.
    heartbeat_echo
        The heartbeat value the PLC logic last saw, None when unknown.
    raw_word
        The status word as read, None when unknown.
    """

    ready: bool
    busy: bool
    fault: bool
    estop: bool
    heartbeat_seen: bool
    watchdog_tripped: bool
    last_accepted_id: int | None
    heartbeat_echo: int | None
    raw_word: int | None

    @property
    def can_accept_command(self) -> bool:
        """Ready, not busy, no fault, no e-stop, watchdog not tripped."""
        return self.ready and not (self.busy or self.fault or self.estop or self.watchdog_tripped)


def decode_status(registers: Sequence[int]) -> PlcStatus:
    """Decode the 3-register status block.

    Parameters
    ----------
    registers
        Status word, last accepted command id, heartbeat echo (each 0..65535).

    Raises
    ------
    ValueError
        Not exactly 3 registers.
    """
    if len(registers) != STATUS_COUNT:
        raise ValueError(f"the status block has {STATUS_COUNT} registers, got {len(registers)}")
    word = int(registers[0])
    bits = StatusBit(word & _KNOWN_BITS)  # undefined bits are reserved and ignored
    return PlcStatus(
        ready=StatusBit.READY in bits,
        busy=StatusBit.BUSY in bits,
        fault=StatusBit.FAULT in bits,
        estop=StatusBit.ESTOP in bits,
        heartbeat_seen=StatusBit.HEARTBEAT_SEEN in bits,
        watchdog_tripped=False,
        last_accepted_id=int(registers[1]),
        heartbeat_echo=int(registers[2]),
        raw_word=word,
    )


def tripped_status() -> PlcStatus:
    """The fail-safe status reported while the watchdog refuses every read."""
    return PlcStatus(ready=False, busy=False, fault=True, estop=False, heartbeat_seen=False,
                     watchdog_tripped=True, last_accepted_id=None, heartbeat_echo=None, raw_word=None)


@dataclass(frozen=True)
class MachineOutputs:
    """The output block: what the PLC drives on the machine.

    Attributes
    ----------
    spindle_enabled
        The polishing spindle is enabled.
    active_command_id
        Id of the command the outputs belong to (0 = none).
    setpoint_nm
        Removal set point per term in nm, shape (n_terms,).
    """

    spindle_enabled: bool
    active_command_id: int
    setpoint_nm: NDArray[np.float64] = field(repr=False)

    @property
    def all_zero(self) -> bool:
        """Every output is zero, as after a watchdog trip."""
        return not self.spindle_enabled and self.active_command_id == 0 and not np.any(self.setpoint_nm)


def decode_outputs(registers: Sequence[int], order: WordOrder) -> MachineOutputs:
    """Decode the output block (``2 + 2 n`` registers) with the block's float32 byte order."""
    if len(registers) < OUTPUT_HEADER_COUNT + 2 or (len(registers) - OUTPUT_HEADER_COUNT) % 2:
        raise ValueError(f"the output block has 2 + 2 n registers, got {len(registers)}")
    setpoint = decode_float32_array(registers[OUTPUT_HEADER_COUNT:], order)
    setpoint.setflags(write=False)
    return MachineOutputs(spindle_enabled=bool(registers[0]), active_command_id=int(registers[1]),
                          setpoint_nm=setpoint)


@dataclass(frozen=True)
class CommandAck:
    """The PLC accepted a command (its last accepted id equals the command's id).

    Attributes
    ----------
    command_id
        The command's id.
    attempts
        Requests it took (more than 1 after a timeout or a malformed reply; retries are idempotent).
    status
        The status read that confirmed the acknowledge.
    """

    command_id: int
    attempts: int
    status: PlcStatus
