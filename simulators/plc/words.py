"""Register words of the simulated PLC: float32 and uint32 in two registers, in the four byte orders.

Re-implemented from the README's table (``A`` = most significant byte; the order names the bytes on
the wire, register 0 high byte first), not imported from the driver's codec.
"""

from __future__ import annotations

import struct

__all__ = ["float_to_words", "uint32_to_words", "words_to_float", "words_to_uint32"]


def _swap_bytes(word: int) -> int:
    return ((word & 0xFF) << 8) | (word >> 8)


def float_to_words(value: float, order: str) -> list[int]:
    """Two registers for a float32 in byte order ``order`` (``A`` = most significant byte)."""
    bits = struct.unpack(">I", struct.pack(">f", value))[0]
    high, low = bits >> 16, bits & 0xFFFF
    return {"ABCD": [high, low], "CDAB": [low, high],
            "BADC": [_swap_bytes(high), _swap_bytes(low)], "DCBA": [_swap_bytes(low), _swap_bytes(high)]}[order]


def words_to_float(words: list[int], order: str) -> float:
    """The float32 in two registers with byte order ``order``."""
    first, second = words
    high, low = {"ABCD": (first, second), "CDAB": (second, first),
                 "BADC": (_swap_bytes(first), _swap_bytes(second)),
                 "DCBA": (_swap_bytes(second), _swap_bytes(first))}[order]
    return float(struct.unpack(">f", struct.pack(">I", (high << 16) | low))[0])


def uint32_to_words(value: int, order: str) -> list[int]:
    """Two registers for an unsigned 32-bit value in byte order ``order`` (as a float32's bytes travel)."""
    high, low = (value >> 16) & 0xFFFF, value & 0xFFFF
    return {"ABCD": [high, low], "CDAB": [low, high],
            "BADC": [_swap_bytes(high), _swap_bytes(low)], "DCBA": [_swap_bytes(low), _swap_bytes(high)]}[order]


def words_to_uint32(words: list[int], order: str) -> int:
    """The unsigned 32-bit value in two registers with byte order ``order``."""
    first, second = words
    high, low = {"ABCD": (first, second), "CDAB": (second, first),
                 "BADC": (_swap_bytes(first), _swap_bytes(second)),
                 "DCBA": (_swap_bytes(second), _swap_bytes(first))}[order]
    return (high << 16) | low
