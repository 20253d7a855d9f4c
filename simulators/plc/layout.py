"""The simulated PLC's register layout (the same meaning as the driver's register map, written apart).

Re-implemented from the register-map description in docs/instruments.md, without importing the
driver's map: a shared misunderstanding must not make both ends agree.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymodbus.simulator import DataType, SimData

from wavestack.simulators.plc.words import float_to_words

__all__ = ["DISPLAY_COUNT", "JOB_COUNT", "MACHINE_COUNT", "OWNER_COUNT", "PlcSimLayout"]

#: Registers of the job block, of the machine block, of the owner block and of the display block.
JOB_COUNT, MACHINE_COUNT, OWNER_COUNT, DISPLAY_COUNT = 8, 7, 4, 8
_ORDERS = ("ABCD", "CDAB", "BADC", "DCBA")


@dataclass(frozen=True)
class PlcSimLayout:
    """The simulated PLC's register layout (same meaning as the driver's register map).

    Attributes
    ----------
    unit_id
        Modbus unit id the PLC answers to.
    self_check_register, self_check_value, self_check_word_order
        2-register float32 constant.
    heartbeat_register, rearm_register
        Single writable registers.
    status_register
        Start of 3 read-only registers: status word, last accepted command id, heartbeat echo.
    command_block, output_block
        ``(start, count)``, count = 2 + 2 n for n terms. Command: id, passes, n float32 removals (nm);
        outputs (read-only): spindle enable, active command id, n float32 set points (nm).
    command_word_order, output_word_order
        Byte order of the float32 values in those blocks.
    watchdog_timeout_s
        Heartbeat watchdog timeout, s.
    pass_duration_s
        Time one polishing pass keeps the PLC busy, s (0: a command completes at once).
    read_function
        Function code every block is read with: 3 (holding registers) or 4 (input registers).
    single_write_function
        Function code of the heartbeat and re-arm writes: 6, or 16 with one register. The command
        block is always written with 16, whole (see :mod:`~wavestack.simulators.plc.access`).
    job_register, machine_register
        Starts of the 8-register job block (action, job id, uint32 CRC-32, uint32 point count,
        float32 total dwell; written whole with 16) and the 7-register read-only machine block
        (state, reason, job id, uint32 points done, uint32 point count); both or neither.
    job_word_order
        Byte order of the 32-bit values in those blocks (None: ``command_word_order``).
    owner_register
        Start of the 4-register owner block (a connection claims ownership with a token written
        there, FC16, whole; it reads as zeros), or None: the first connection that beats owns.
    display_register
        Start of the 8-register result display block (the owner writes it whole with FC16; every
        connection reads it: the panel's HMI), or None.
    """

    unit_id: int
    self_check_register: int
    self_check_value: float
    self_check_word_order: str
    heartbeat_register: int
    rearm_register: int
    status_register: int
    command_block: tuple[int, int]
    output_block: tuple[int, int]
    command_word_order: str
    output_word_order: str
    watchdog_timeout_s: float
    pass_duration_s: float = 0.0
    read_function: int = 3
    single_write_function: int = 6
    job_register: int | None = None
    machine_register: int | None = None
    job_word_order: str | None = None
    owner_register: int | None = None
    display_register: int | None = None

    def __post_init__(self) -> None:
        if (self.job_register is None) != (self.machine_register is None):
            raise ValueError("job_register and machine_register come together: set both or neither")
        if self.read_function not in (3, 4):
            raise ValueError(f"read_function must be 3 or 4, got {self.read_function!r}")
        if self.single_write_function not in (6, 16):
            raise ValueError(f"single_write_function must be 6 or 16, got {self.single_write_function!r}")
        for order in (self.self_check_word_order, self.command_word_order, self.output_word_order,
                      self.job_word_order or self.command_word_order):
            if order not in _ORDERS:
                raise ValueError(f"unknown word order {order!r}; expected one of {_ORDERS}")
        if self.command_block[1] != self.output_block[1] or self.command_block[1] < 4 or self.command_block[1] % 2:
            raise ValueError(f"command and output blocks must both be 2 + 2 n registers, got "
                             f"{self.command_block[1]} and {self.output_block[1]}")
        if self.pass_duration_s < 0:
            raise ValueError(f"pass_duration_s must be >= 0, got {self.pass_duration_s}")
        spans = sorted([(self.self_check_register, 2), (self.heartbeat_register, 1), (self.rearm_register, 1),
                        (self.status_register, 3), self.command_block, self.output_block,
                        *([(self.job_register, JOB_COUNT), (self.machine_register, MACHINE_COUNT)]
                          if self.job_register is not None and self.machine_register is not None else []),
                        *([(self.owner_register, OWNER_COUNT)] if self.owner_register is not None else []),
                        *([(self.display_register, DISPLAY_COUNT)] if self.display_register is not None else [])])
        for (first, count), (second, _) in zip(spans, spans[1:]):
            if second < first + count:
                raise ValueError(f"register blocks starting at {first} and {second} overlap")

    @property
    def n_terms(self) -> int:
        """Number of removal terms."""
        return (self.command_block[1] - 2) // 2

    def simdata(self) -> list[SimData]:
        """pymodbus register blocks: writable heartbeat, re-arm, command, job, owner and display; the rest read-only."""
        constant = float_to_words(self.self_check_value, self.self_check_word_order)
        return [
            SimData(self.self_check_register, values=constant, datatype=DataType.REGISTERS, readonly=True),
            SimData(self.heartbeat_register, values=0, datatype=DataType.REGISTERS),
            SimData(self.rearm_register, values=0, datatype=DataType.REGISTERS),
            SimData(self.status_register, count=3, values=0, datatype=DataType.REGISTERS, readonly=True),
            SimData(self.command_block[0], count=self.command_block[1], values=0, datatype=DataType.REGISTERS),
            SimData(self.output_block[0], count=self.output_block[1], values=0, datatype=DataType.REGISTERS,
                    readonly=True),
            *([SimData(self.job_register, count=JOB_COUNT, values=0, datatype=DataType.REGISTERS),
               SimData(self.machine_register, count=MACHINE_COUNT, values=0, datatype=DataType.REGISTERS,
                       readonly=True)] if self.job_register is not None and self.machine_register is not None else []),
            *([SimData(self.owner_register, count=OWNER_COUNT, values=0, datatype=DataType.REGISTERS)]
              if self.owner_register is not None else []),
            *([SimData(self.display_register, count=DISPLAY_COUNT, values=0, datatype=DataType.REGISTERS)]
              if self.display_register is not None else []),
        ]

    @property
    def has_jobs(self) -> bool:
        """Whether the map carries the job and machine blocks."""
        return self.job_register is not None and self.machine_register is not None

    @property
    def job_order(self) -> str:
        """Byte order of the 32-bit values in the job and machine blocks."""
        return self.job_word_order or self.command_word_order
