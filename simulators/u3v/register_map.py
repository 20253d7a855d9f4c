"""A GenCP register address space: registers, the map that routes reads and writes, status codes.

Access rules (GenCP status codes): a read or write touching an unmapped byte -> INVALID_ADDRESS; a
read of a write-only register -> ACCESS_DENIED; a write touching a read-only register -> WRITE_PROTECT
(checked first); a write that covers only part of a register -> BAD_ALIGNMENT. A read may cover
several adjacent registers or part of one (the host reads the XML file in chunks). Range checks
(INVALID_PARAMETER) belong to the registers' own write functions.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

AccessMode = Literal["RO", "RW", "WO"]


class GenCPStatus(IntEnum):
    """Acknowledge status codes: GenCP 1.x, plus the USB3 Vision streaming codes (0xA0xx)."""

    SUCCESS = 0x0000
    NOT_IMPLEMENTED = 0x8001
    INVALID_PARAMETER = 0x8002
    INVALID_ADDRESS = 0x8003
    WRITE_PROTECT = 0x8004
    BAD_ALIGNMENT = 0x8005
    ACCESS_DENIED = 0x8006
    BUSY = 0x8007
    MSG_TIMEOUT = 0x800B
    INVALID_HEADER = 0x800E
    WRONG_CONFIG = 0x800F
    GENERIC_ERROR = 0x8FFF
    SI_PAYLOAD_SIZE_NOT_ALIGNED = 0xA003
    SI_REGISTERS_INCONSISTENT = 0xA004
    DATA_DISCARDED = 0xA100


@dataclass(frozen=True)
class Register:
    """One mapped register: ``read()`` returns exactly ``length`` bytes, ``write(data)`` a status."""

    name: str
    address: int
    length: int
    access: AccessMode
    read: Callable[[], bytes]
    write: Callable[[bytes], GenCPStatus] | None = None


class RegisterMap:
    """Address space made of non-overlapping :class:`Register` objects.

    Parameters
    ----------
    registers
        The registers; overlapping ones raise ``ValueError``.
    """

    def __init__(self, registers: Iterable[Register]) -> None:
        self._registers = sorted(registers, key=lambda r: r.address)
        self._starts = [r.address for r in self._registers]
        for before, after in zip(self._registers, self._registers[1:]):
            if before.address + before.length > after.address:
                raise ValueError(f"registers {before.name} and {after.name} overlap")
        if any(r.length <= 0 for r in self._registers):
            raise ValueError("every register needs a positive length")

    def __iter__(self) -> Iterator[Register]:
        return iter(self._registers)

    def _span(self, address: int, length: int) -> list[Register] | None:
        """Registers covering ``[address, address + length)`` without a gap, or None."""
        first = bisect.bisect_right(self._starts, address) - 1
        if first < 0 or length <= 0:
            return None
        reg = self._registers[first]
        covered = reg.address + reg.length
        if address >= covered:
            return None
        last = first
        while covered < address + length:
            last += 1
            if last >= len(self._registers) or self._registers[last].address != covered:
                return None
            covered += self._registers[last].length
        return self._registers[first:last + 1]

    def read(self, address: int, length: int) -> tuple[GenCPStatus, bytes]:
        """Read ``length`` bytes at ``address``; (status, data), data empty unless SUCCESS."""
        span = self._span(address, length)
        if span is None:
            return GenCPStatus.INVALID_ADDRESS, b""
        if any(r.access == "WO" for r in span):
            return GenCPStatus.ACCESS_DENIED, b""
        data = b"".join(r.read() for r in span)
        start = address - span[0].address
        return GenCPStatus.SUCCESS, data[start:start + length]

    def write(self, address: int, data: bytes) -> tuple[GenCPStatus, int]:
        """Write ``data`` at ``address``; (status, bytes written). Whole registers only."""
        span = self._span(address, len(data))
        if span is None:
            return GenCPStatus.INVALID_ADDRESS, 0
        if any(r.access == "RO" or r.write is None for r in span):
            return GenCPStatus.WRITE_PROTECT, 0
        if span[0].address != address or span[-1].address + span[-1].length != address + len(data):
            return GenCPStatus.BAD_ALIGNMENT, 0
        written = 0
        for reg in span:
            assert reg.write is not None  # checked above
            status = reg.write(data[written:written + reg.length])
            if status != GenCPStatus.SUCCESS:
                return status, written
            written += reg.length
        return GenCPStatus.SUCCESS, written
