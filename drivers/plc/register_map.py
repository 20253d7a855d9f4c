"""The polishing-station PLC's register map, the command block's layout and the write allow-list.

Every address the driver touches is named here, as frozen values built from the configuration, so
a register map is checked once (no overlaps, counts that fit one Modbus request, function codes that
make sense) and the driver never writes a literal address. The host may write only these places:
the heartbeat register, the re-arm register, the command block, the job block, the owner block
and the display block (each block whole, in one request), each with its configured function code;
:meth:`RegisterMap.check_write` refuses anything else before a byte goes on the wire.

Layout of the blocks (``n`` = number of removal terms, ``(count - 2) / 2``):

- self-check: float32, a known constant (2 registers);
- heartbeat: uint16, incremented by the host every cycle (mod 65536);
- re-arm: uint16, writing 1 re-arms a tripped watchdog;
- status (3 registers): status word (bits: see :class:`~wavestack.drivers.plc.status.StatusBit`),
  last accepted command id, heartbeat echo;
- command (``2 + 2 n``): uint16 command id (1..65535; 0 = none), uint16 passes, ``n`` float32
  removal amplitudes in nm (one per Zernike term, in the station's term order);
- outputs (``2 + 2 n``, read-only): uint16 spindle enable, uint16 active command id, ``n`` float32
  removal set points in nm. The watchdog zeroes this block.
- job (8, optional, FC16 whole): uint16 action (1 load, 2 start, 3 abort), uint16 job id, uint32
  CRC-32 of the job file's body, uint32 point count, float32 total dwell s (see :mod:`.jobs`);
- machine (7, optional, read-only): uint16 state, uint16 reason, uint16 job id, uint32 points done,
  uint32 point count;
- owner (4, optional, FC16 whole, reads as zeros): the host's 64-bit ownership token. The PLC takes
  heartbeat, command and job writes from one connection only, the one that claimed it with its
  token, until the watchdog trips; the same host reclaims it after a reconnect with the same
  token; the re-arm register takes anyone's write (the operator's). Without this block the PLC
  gives ownership to the first connection that beats.
- display (8, optional, FC16 whole, the owner's; anyone reads it): the last result for the
  machine's panel: counter, flags (valid, figures), residual RMS and PVr (float32 nm of surface),
  spec verdict and limiting quantity codes (:mod:`.display`).

The command block keeps publishing the measured terms for the machine's display; removal happens
only through jobs (job file + job block).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wavestack.drivers._checks import is_integral_in
from wavestack.drivers.plc.codec import (WORD_ORDERS, WordOrder, encode_float32, encode_float32_array, encode_uint32,
                                         round_to_float32)
from wavestack.drivers.plc.display import DISPLAY_BLOCK_COUNT, ResultDisplay, encode_display
from wavestack.drivers.plc.jobs import JOB_BLOCK_COUNT, MACHINE_BLOCK_COUNT, MAX_JOB_ID, JobAction
from wavestack.drivers.plc.register_block import RegisterBlock, WriteRefused

#: Registers of the owner block: a 64-bit token, four uint16.
OWNER_COUNT = 4

__all__ = [
    "COMMAND_HEADER_COUNT",
    "MAX_READ_COUNT",
    "MAX_WRITE_COUNT",
    "OUTPUT_HEADER_COUNT",
    "OWNER_COUNT",
    "STATUS_COUNT",
    "RegisterBlock",
    "RegisterMap",
    "WriteRefused",
    "registers_fit",
]

#: Registers in the status block: status word, last accepted command id, heartbeat echo.
STATUS_COUNT = 3
#: Registers before the float32 terms in the command block: command id, passes.
COMMAND_HEADER_COUNT = 2
#: Registers before the float32 terms in the output block: spindle enable, active command id.
OUTPUT_HEADER_COUNT = 2
#: Modbus limits per request: FC3/FC4 read at most 125 registers, FC16 writes at most 123.
MAX_READ_COUNT = 125
MAX_WRITE_COUNT = 123

_READ_FUNCTIONS = (3, 4)
_SINGLE_WRITE_FUNCTIONS = (6, 16)
_BLOCK_WRITE_FUNCTIONS = (16,)


@dataclass(frozen=True)
class RegisterMap:
    """Where everything lives in the PLC, checked for consistency when built.

    Build it with :meth:`build` from configuration values; the constructor takes finished blocks.

    Attributes
    ----------
    unit_id
        Modbus unit (slave) id, 0..255.
    self_check_value
        The constant the self-check block must decode to.
    self_check, heartbeat, rearm, status, command, output
        The blocks (see the module docstring for their layouts).
    job, machine
        The job block and the machine-state block, both or neither (None: a PLC without jobs).
    owner
        The owner block (None: the PLC gives ownership to the first connection that beats).
    display
        The result display block (None: the PLC shows no results).
    """

    unit_id: int
    self_check_value: float
    self_check: RegisterBlock
    heartbeat: RegisterBlock
    rearm: RegisterBlock
    status: RegisterBlock
    command: RegisterBlock
    output: RegisterBlock
    job: RegisterBlock | None = None
    machine: RegisterBlock | None = None
    owner: RegisterBlock | None = None
    display: RegisterBlock | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.unit_id <= 255:
            raise ValueError(f"unit_id must be 0..255, got {self.unit_id}")
        if not math.isfinite(self.self_check_value):
            raise ValueError(f"self_check_value must be finite, got {self.self_check_value}")
        try:
            round_to_float32(self.self_check_value)
        except ValueError:
            raise ValueError(f"self_check_value must lie within the float32 range (|x| <= 3.4e38) that the "
                             f"self-check block holds, got {self.self_check_value!r}") from None
        expected = {"self_check": 2, "heartbeat": 1, "rearm": 1, "status": STATUS_COUNT, "job": JOB_BLOCK_COUNT,
                    "machine": MACHINE_BLOCK_COUNT, "owner": OWNER_COUNT, "display": DISPLAY_BLOCK_COUNT}
        if (self.job is None) != (self.machine is None):
            raise ValueError("the job block and the machine block come together: configure both or neither")
        for block in self.blocks():
            if not (0 <= block.start and block.stop <= 65536 and block.count >= 1):
                raise ValueError(f"{block.name} block [{block.start}, {block.count}] leaves the address range 0..65535")
            if block.name in expected and block.count != expected[block.name]:
                raise ValueError(f"{block.name} block must be {expected[block.name]} register(s), got {block.count}")
            if block.read_function not in _READ_FUNCTIONS:
                raise ValueError(f"{block.name} block: read function code must be 3 or 4, got {block.read_function}")
            if block.count > MAX_READ_COUNT:
                raise ValueError(f"{block.name} block: {block.count} registers exceed one read ({MAX_READ_COUNT})")
        for block in (self.command, self.output):
            if block.count < COMMAND_HEADER_COUNT + 2 or (block.count - COMMAND_HEADER_COUNT) % 2:
                raise ValueError(f"{block.name} block must be 2 + 2 n registers with n >= 1, got {block.count}")
        if self.command.count != self.output.count:
            raise ValueError(f"command block ({self.command.count} registers) and output block "
                             f"({self.output.count}) must hold the same number of terms")
        if self.command.count > MAX_WRITE_COUNT:
            raise ValueError(f"command block: {self.command.count} registers exceed one FC16 write ({MAX_WRITE_COUNT})")
        for block, codes in ((self.heartbeat, _SINGLE_WRITE_FUNCTIONS), (self.rearm, _SINGLE_WRITE_FUNCTIONS),
                             (self.command, _BLOCK_WRITE_FUNCTIONS),
                             *((block, _BLOCK_WRITE_FUNCTIONS) for block in (self.job, self.owner, self.display)
                               if block is not None)):
            if block.write_function not in codes:
                raise ValueError(f"{block.name} block: write function code must be one of {codes}, "
                                 f"got {block.write_function}")
        for block in (self.self_check, self.status, self.output, self.machine):
            if block is not None and block.writable:
                raise ValueError(f"{block.name} block must be read-only")
        ordered = sorted(self.blocks(), key=lambda b: b.start)
        for first, second in zip(ordered, ordered[1:]):
            if second.start < first.stop:
                raise ValueError(f"{first.name} block (registers {first.start}-{first.stop - 1}) overlaps "
                                 f"{second.name} block (registers {second.start}-{second.stop - 1})")

    @classmethod
    def build(
        cls,
        *,
        unit_id: int,
        word_order: WordOrder,
        self_check_register: int,
        self_check_value: float,
        heartbeat_register: int,
        rearm_register: int,
        status_register: int,
        command_block: tuple[int, int],
        output_block: tuple[int, int],
        read_function: int = 3,
        single_write_function: int = 6,
        block_write_function: int = 16,
        self_check_word_order: WordOrder | None = None,
        command_word_order: WordOrder | None = None,
        output_word_order: WordOrder | None = None,
        job_register: int | None = None,
        machine_register: int | None = None,
        owner_register: int | None = None,
        display_register: int | None = None,
    ) -> RegisterMap:
        """A register map from configuration values.

        Parameters
        ----------
        unit_id
            Modbus unit id, 0..255.
        word_order
            Default float32 byte order (``ABCD``, ``CDAB``, ``BADC``, ``DCBA``) of every block.
        self_check_register, self_check_value
            Start of the 2-register float32 constant and the value it must decode to.
        heartbeat_register, rearm_register, status_register
            Addresses of the heartbeat, the re-arm register and the 3-register status block.
        command_block, output_block
            ``(start, count)`` each; count = 2 + 2 n for n removal terms.
        read_function, single_write_function, block_write_function
            Function codes: reads (3 or 4), heartbeat and re-arm writes (6 or 16), command writes (16).
        self_check_word_order, command_word_order, output_word_order
            Per-block byte order overriding ``word_order`` (None = use ``word_order``).
        job_register, machine_register
            Starts of the 8-register job block (written with ``block_write_function``) and the
            7-register machine block (read-only); both or neither (None: no jobs). Their uint32 and
            float32 values use ``word_order``.
        owner_register
            Start of the 4-register owner block (written with ``block_write_function``), or None.
        display_register
            Start of the 8-register display block (written with ``block_write_function``, float32
            in ``word_order``), or None.

        Raises
        ------
        ValueError
            Unknown byte order, overlapping blocks, wrong counts or function codes.
        """
        for order in (word_order, self_check_word_order, command_word_order, output_word_order):
            if order is not None and order not in WORD_ORDERS:
                raise ValueError(f"unknown word order {order!r}; expected one of {', '.join(WORD_ORDERS)}")
        n_terms = (command_block[1] - COMMAND_HEADER_COUNT) // 2
        terms = f"float32[{n_terms}]"
        return cls(
            unit_id=unit_id,
            self_check_value=float(self_check_value),
            self_check=RegisterBlock("self_check", self_check_register, 2, "float32", read_function, None,
                                     self_check_word_order or word_order,
                                     f"constant {self_check_value!r}, checked at start-up"),
            heartbeat=RegisterBlock("heartbeat", heartbeat_register, 1, "uint16", read_function,
                                    single_write_function, None,
                                    "host increments every cycle; only a change feeds the watchdog"),
            rearm=RegisterBlock("rearm", rearm_register, 1, "uint16", read_function, single_write_function, None,
                                "write 1 to re-arm a tripped watchdog"),
            status=RegisterBlock("status", status_register, STATUS_COUNT,
                                 "uint16 status word, uint16 last accepted id, uint16 heartbeat echo",
                                 read_function, None, None,
                                 "bit 0 ready, 1 busy, 2 fault, 3 e-stop, 4 heartbeat seen"),
            command=RegisterBlock("command", command_block[0], command_block[1],
                                  f"uint16 command id, uint16 passes, {terms} removal_nm", read_function,
                                  block_write_function, command_word_order or word_order,
                                  "measured terms for the display (removal only through jobs); once per id; one request"),
            output=RegisterBlock("output", output_block[0], output_block[1],
                                 f"uint16 spindle enable, uint16 active id, {terms} set point nm", read_function,
                                 None, output_word_order or word_order, "machine outputs; the watchdog zeroes them"),
            job=None if job_register is None else RegisterBlock(
                "job", job_register, JOB_BLOCK_COUNT,
                "uint16 action, uint16 job id, uint32 CRC-32, uint32 point count, float32 total dwell s",
                read_function, block_write_function, word_order,
                "action 1 load (reads job-NNNNN.wsjob), 2 start, 3 abort; written in one request"),
            machine=None if machine_register is None else RegisterBlock(
                "machine", machine_register, MACHINE_BLOCK_COUNT,
                "uint16 state, uint16 reason, uint16 job id, uint32 points done, uint32 point count",
                read_function, None, word_order,
                "state 0 idle, 1 loaded, 2 running, 3 done, 4 aborted, 5 fault, 6 loading; reason code (docs/instruments.md)"),
            owner=None if owner_register is None else RegisterBlock(
                "owner", owner_register, OWNER_COUNT, "uint16[4] token", read_function, block_write_function, None,
                "the host's ownership token; written whole; reads as zeros"),
            display=None if display_register is None else RegisterBlock(
                "display", display_register, DISPLAY_BLOCK_COUNT,
                "uint16 result counter, uint16 flags, float32 residual RMS nm, float32 PVr nm, uint16 spec, "
                "uint16 limiting", read_function, block_write_function, word_order,
                "the last result for the machine's panel (owner writes, anyone reads); codes: docs/instruments.md"),
        )

    @property
    def n_terms(self) -> int:
        """Number of removal terms the command block carries."""
        return (self.command.count - COMMAND_HEADER_COUNT) // 2

    @property
    def device(self) -> str:
        """How errors name the PLC."""
        return f"PLC unit {self.unit_id}"

    def blocks(self) -> tuple[RegisterBlock, ...]:
        """Every block, in address-independent fixed order."""
        jobs = (self.job, self.machine) if self.job is not None and self.machine is not None else ()
        optional = tuple(block for block in (self.owner, self.display) if block is not None)
        return (self.self_check, self.heartbeat, self.rearm, self.status, self.command, self.output, *jobs, *optional)

    def check_write(self, address: int, count: int, function_code: int) -> RegisterBlock:
        """The writable block a write falls in, or refuse it.

        Parameters
        ----------
        address, count
            First register and number of registers to write.
        function_code
            The function code the write would use.

        Returns
        -------
        RegisterBlock
            The heartbeat, re-arm, command, job, owner or display block holding the whole write.

        Raises
        ------
        WriteRefused
            The write is not entirely inside one writable block, does not use that block's
            configured function code (FC6 can only write one register), or covers only part of the
            command or job block (the PLC refuses it: a new id would act on stale registers).
        """
        allowed = ", ".join(b.describe() for b in self.blocks() if b.writable)
        what = f"register {address}" if count == 1 else f"registers {address}-{address + count - 1}"
        for block in self.blocks():
            if block.writable and block.contains(address, count):
                if function_code != block.write_function or (function_code == 6 and count != 1):
                    raise WriteRefused(self.device, f"refusing to write {what} with FC{function_code}: the "
                                       f"{block.name} block is written with FC{block.write_function} only")
                if block.count > 1 and (address, count) != (block.start, block.count):
                    raise WriteRefused(self.device, f"refusing to write {what}: the {block.name} block "
                                       f"(registers {block.start}-{block.stop - 1}) is written whole, in one "
                                       f"FC{block.write_function} request")
                return block
        raise WriteRefused(self.device, f"refusing to write {what} (FC{function_code}): the host may write only "
                           f"{allowed}")

    def encode_command(self, command_id: int, passes: int, removal_nm: ArrayLike) -> list[int]:
        """The command block's registers for one removal command.

        Parameters
        ----------
        command_id
            1..65535; a command takes effect once, when the PLC sees this id change.
        passes
            Number of polishing passes, 1..65535.
        removal_nm
            Removal per term in nm, shape (n_terms,), finite and within float32 range.

        Returns
        -------
        list[int]
            ``self.command.count`` registers.

        Raises
        ------
        ValueError
            An id or pass count out of range, a wrong shape or a non-finite removal.
        """
        if not is_integral_in(command_id, 1, 0xFFFF):
            raise ValueError(f"command_id must be an integer 1..65535 (0 means none), got {command_id!r}")
        if not is_integral_in(passes, 1, 0xFFFF):
            raise ValueError(f"passes must be an integer 1..65535, got {passes!r}")
        values = np.asarray(removal_nm, dtype=np.float64)
        if values.shape != (self.n_terms,):
            raise ValueError(f"removal_nm must have shape ({self.n_terms},), got {values.shape}")
        if not np.all(np.isfinite(values)):
            raise ValueError("removal_nm must be finite")
        assert self.command.word_order is not None
        return [int(command_id), int(passes), *encode_float32_array(values, self.command.word_order)]

    def encode_job(self, action: JobAction, job_id: int, crc32: int, point_count: int,
                   total_dwell_s: float) -> list[int]:
        """The job block's registers for one job action.

        Parameters
        ----------
        action
            LOAD, START or ABORT.
        job_id
            1..65535.
        crc32, point_count
            Unsigned 32-bit values (the job file's body CRC-32 and its number of points).
        total_dwell_s
            Total dwell, s, finite and >= 0 (rounded to float32 on the wire).

        Raises
        ------
        ValueError
            No job block in this map, or a value out of range.
        """
        if self.job is None:
            raise ValueError(f"{self.device}: the register map has no job block (configure job_register)")
        if not is_integral_in(job_id, 1, MAX_JOB_ID):
            raise ValueError(f"job_id must be an integer 1..{MAX_JOB_ID} (0 means none), got {job_id!r}")
        if not (math.isfinite(total_dwell_s) and total_dwell_s >= 0):
            raise ValueError(f"total_dwell_s must be finite and >= 0, got {total_dwell_s!r}")
        order = self.job.word_order
        assert order is not None
        return [int(JobAction(action)), int(job_id), *encode_uint32(crc32, order), *encode_uint32(point_count, order),
                *encode_float32(total_dwell_s, order)]

    def encode_display(self, display: ResultDisplay) -> list[int]:
        """The display block's registers for one result (:func:`~.display.encode_display`).

        Raises
        ------
        ValueError
            No display block in this map, or a figure beyond the float32 range.
        """
        if self.display is None or self.display.word_order is None:
            raise ValueError(f"{self.device}: the register map has no display block (configure display_register)")
        return encode_display(display, self.display.word_order)

    def markdown_table(self) -> str:
        """The map as a Markdown table (address, count, type, access, function codes, meaning)."""
        lines = ["| address | count | type | access | function codes | meaning |",
                 "|---|---|---|---|---|---|"]
        for block in sorted(self.blocks(), key=lambda b: b.start):
            address = str(block.start) if block.count == 1 else f"{block.start}-{block.stop - 1}"
            access = "read/write" if block.writable else "read-only"
            codes = f"read {block.read_function}" + (f", write {block.write_function}" if block.writable else "")
            order = f" ({block.word_order})" if block.word_order else ""
            lines.append(f"| {address} | {block.count} | {block.layout}{order} | {access} | {codes} | "
                         f"{block.name}: {block.meaning} |")
        return "\n".join(lines)


def registers_fit(values: Sequence[int]) -> bool:
    """Whether every value is a 16-bit unsigned register value."""
    return all(not isinstance(v, bool) and isinstance(v, int) and 0 <= v <= 0xFFFF for v in values)
