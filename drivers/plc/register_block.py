"""A contiguous run of PLC registers with one meaning, and the error for a write outside the allow-list.

The register map (:mod:`.register_map`) is built from these blocks; each block knows its address
range, its types and the function codes it is read and written with.
"""

from __future__ import annotations

from dataclasses import dataclass

from wavestack.drivers.errors import LimitError
from wavestack.drivers.plc.codec import WordOrder

__all__ = ["RegisterBlock", "WriteRefused"]


class WriteRefused(LimitError):
    """A write outside the allow-list (the map's writable blocks) or with the wrong function code;
    refused before anything was sent."""


@dataclass(frozen=True)
class RegisterBlock:
    """A contiguous run of holding registers with one meaning.

    Attributes
    ----------
    name
        ``"self_check"``, ``"heartbeat"``, ``"rearm"``, ``"status"``, ``"command"``, ``"output"``,
        ``"job"``, ``"machine"``, ``"owner"`` or ``"display"``.
    start
        Address of the first register (0-based protocol address, as on the wire).
    count
        Number of 16-bit registers.
    layout
        The types inside, e.g. ``"float32"`` or ``"uint16 id, uint16 passes, float32[15]"``.
    read_function
        Function code used to read it: 3 (holding registers) or 4 (input registers).
    write_function
        Function code used to write it (6 or 16), or None for a block the host must not write.
    word_order
        Byte order of the float32 values inside (None for a block without float32).
    meaning
        One line for the README table.
    """

    name: str
    start: int
    count: int
    layout: str
    read_function: int
    write_function: int | None
    word_order: WordOrder | None = None
    meaning: str = ""

    @property
    def stop(self) -> int:
        """One past the last address."""
        return self.start + self.count

    @property
    def writable(self) -> bool:
        """Whether the host may write this block."""
        return self.write_function is not None

    def contains(self, address: int, count: int = 1) -> bool:
        """Whether registers ``address .. address + count - 1`` all lie in this block."""
        return self.start <= address and address + count <= self.stop and count >= 1

    def describe(self) -> str:
        """``"heartbeat (register 10, FC6)"`` or ``"command (registers 100-131, FC16)"``."""
        where = f"register {self.start}" if self.count == 1 else f"registers {self.start}-{self.stop - 1}"
        code = f"FC{self.write_function}" if self.writable else f"read-only, FC{self.read_function}"
        return f"{self.name} ({where}, {code})"
