"""Register values as GenApi lays them out, and the cache of what was read, without I/O of its own.

:func:`decode_integer` / :func:`encode_integer` turn register bytes into integers and back
(endianness, sign, the bit field of a ``MaskedIntReg``); :class:`RegisterCache` holds the bytes
last read from or written to each register node, by the node's ``Cachable`` policy, and forgets
them when a write could have changed them.

Bit numbering follows GenApi: in a little-endian register bit 0 is the least significant bit; in a
big-endian register bit 0 is the most significant one, so ``LSB`` >= ``MSB`` there.

Reference: EMVA GenICam Standard, GenApi, sections "IntReg", "MaskedIntReg", "Caching".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

Endianness = Literal["LittleEndian", "BigEndian"]
Cachable = Literal["NoCache", "WriteThrough", "WriteAround"]


class Port(Protocol):
    """The device's register space, as a transport offers it to the node map.

    ``read`` returns exactly ``length`` bytes from ``address``; ``write`` stores ``data`` there.
    Both raise a ``DeviceError`` (timeout, refusal by the device, disconnection).
    """

    def read(self, address: int, length: int) -> bytes:
        """``length`` bytes at ``address``."""
        ...

    def write(self, address: int, data: bytes) -> None:
        """Store ``data`` at ``address``."""
        ...


@dataclass(frozen=True)
class BitField:
    """Where an integer lives in a register of ``length`` bytes, in little-endian bit numbers.

    Attributes
    ----------
    low, high
        Least and most significant bit of the field (0 = the register's least significant bit).
    """

    low: int
    high: int

    @property
    def width(self) -> int:
        return self.high - self.low + 1


def bit_field(lsb: int, msb: int, length: int, endianness: Endianness) -> BitField:
    """The field of a ``MaskedIntReg`` given its ``LSB``/``MSB`` (or ``Bit``) as written in the XML.

    Raises
    ------
    ValueError
        Bits outside the register, or LSB and MSB in the wrong order for its endianness.
    """
    bits = 8 * length
    if endianness == "BigEndian":
        lsb, msb = bits - 1 - lsb, bits - 1 - msb
    if not (0 <= lsb <= msb < bits):
        raise ValueError(f"bits LSB {lsb}..MSB {msb} do not lie in a {length}-byte {endianness} register")
    return BitField(lsb, msb)


def decode_integer(raw: bytes, endianness: Endianness, signed: bool, field: BitField | None = None) -> int:
    """The integer in ``raw`` (the whole register, or its bit field), sign-extended when ``signed``.

    Example
    -------
    >>> decode_integer(bytes([0x80, 0, 0, 1]), "BigEndian", False, bit_field(0, 0, 4, "BigEndian"))
    1
    """
    value = int.from_bytes(raw, "big" if endianness == "BigEndian" else "little")
    width = 8 * len(raw)
    if field is not None:
        value = (value >> field.low) & ((1 << field.width) - 1)
        width = field.width
    if signed and value >> (width - 1):
        value -= 1 << width
    return value


def integer_range(length: int, signed: bool, field: BitField | None = None) -> tuple[int, int]:
    """Smallest and largest integer a register (or its bit field) holds."""
    width = field.width if field is not None else 8 * length
    return (-(1 << (width - 1)), (1 << (width - 1)) - 1) if signed else (0, (1 << width) - 1)


def encode_integer(value: int, length: int, endianness: Endianness, signed: bool, field: BitField | None = None,
                   old: bytes | None = None) -> bytes:
    """Register bytes holding ``value`` (in the bit field, keeping ``old``'s other bits).

    Raises
    ------
    ValueError
        ``value`` does not fit the register or field.
    """
    low, high = integer_range(length, signed, field)
    if not low <= value <= high:
        raise ValueError(f"{value} does not fit {'a signed' if signed else 'an unsigned'} field of "
                         f"{field.width if field else 8 * length} bits")
    order: Literal["big", "little"] = "big" if endianness == "BigEndian" else "little"
    if field is None:
        return (value & ((1 << (8 * length)) - 1)).to_bytes(length, order)
    mask = ((1 << field.width) - 1) << field.low
    current = int.from_bytes(old if old is not None else bytes(length), order)
    merged = (current & ~mask) | ((value << field.low) & mask)
    return merged.to_bytes(length, order)


class RegisterCache:
    """Register bytes, kept by the ``Cachable`` policy of the node that read or wrote them.

    Entries are keyed by port, address and length, so the entries of a ``StructReg`` and the
    ``MaskedIntReg`` nodes of one register share one read. ``WriteThrough`` (the default) keeps
    what was read and what was written; ``WriteAround`` keeps what was read and forgets on write;
    ``NoCache`` keeps nothing. A write also forgets every cached register that overlaps the written
    bytes on the same port, and :meth:`forget` drops the registers of the nodes a write invalidates
    (``pInvalidator``), which the evaluator works out.
    """

    def __init__(self) -> None:
        self._entries: dict[tuple[str, int, int], bytes] = {}
        self._keys: dict[str, tuple[str, int, int]] = {}  # node -> the register it last used

    def read(self, node: str, port: str, address: int, length: int, policy: Cachable,
             fetch: Callable[[], bytes]) -> bytes:
        """The register's bytes: from the cache when held (and the node's policy allows), else ``fetch()``."""
        key = (port, address, length)
        self._keys[node] = key
        if policy != "NoCache" and key in self._entries:
            return self._entries[key]
        data = fetch()
        if policy != "NoCache":
            self._entries[key] = data
        return data

    def wrote(self, node: str, port: str, address: int, data: bytes, policy: Cachable) -> None:
        """Record a write of ``data`` at ``address`` through ``node`` (after the device took it)."""
        end = address + len(data)
        for key in [k for k in self._entries if k[0] == port and k[1] < end and address < k[1] + k[2]]:
            del self._entries[key]
        key = (port, address, len(data))
        self._keys[node] = key
        if policy == "WriteThrough":
            self._entries[key] = bytes(data)

    def forget(self, nodes: set[str] | frozenset[str]) -> None:
        """Drop the registers the named nodes last used."""
        for name in nodes:
            key = self._keys.get(name)
            if key is not None:
                self._entries.pop(key, None)

    def clear(self) -> None:
        """Drop everything (a new connection, or a device reset)."""
        self._entries.clear()
