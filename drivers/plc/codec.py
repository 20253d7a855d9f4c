"""32-bit values in two 16-bit Modbus registers, in the four byte orders PLCs use.

Modbus itself only defines 16-bit registers, each sent high byte first. A 32-bit value (IEEE-754
float32 or uint32) spans two registers, and vendors disagree on how its four bytes are laid out.
Name the value's big-endian bytes ``A B C D`` (``A`` is the most significant byte: for a float32 the
sign and the high exponent bits; ``D`` the least significant mantissa byte). The order names the
bytes as they appear on the wire, register 0 high byte first:

========  ========================  ========================  =======================================
order     register 0 (hi, lo byte)  register 1 (hi, lo byte)  seen on
========  ========================  ========================  =======================================
``ABCD``  A, B                      C, D                      big-endian ("high word first"), Siemens
``CDAB``  C, D                      A, B                      word swap ("low word first"), Modicon
``BADC``  B, A                      D, C                      byte swap inside each word
``DCBA``  D, C                      B, A                      little-endian, e.g. some PC-based PLCs
========  ========================  ========================  =======================================

pymodbus's converters only swap words (``ABCD``/``CDAB``), so this module does all four itself. It
is pure: no I/O, no pymodbus.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.drivers._checks import is_integral_in

__all__ = [
    "WORD_ORDERS",
    "WordOrder",
    "decode_float32",
    "decode_float32_array",
    "decode_uint32",
    "encode_float32",
    "encode_float32_array",
    "encode_uint32",
    "round_to_float32",
]

WordOrder = Literal["ABCD", "CDAB", "BADC", "DCBA"]
#: The four byte orders, in the order of the table above.
WORD_ORDERS: tuple[WordOrder, ...] = get_args(WordOrder)

# For each order: wire position i (register 0 high, register 0 low, register 1 high, register 1 low)
# carries the value's big-endian byte _WIRE_FROM_VALUE[order][i] (0 = A ... 3 = D).
_WIRE_FROM_VALUE: dict[str, tuple[int, int, int, int]] = {
    "ABCD": (0, 1, 2, 3),
    "CDAB": (2, 3, 0, 1),
    "BADC": (1, 0, 3, 2),
    "DCBA": (3, 2, 1, 0),
}


def _check_order(order: str) -> tuple[int, int, int, int]:
    try:
        return _WIRE_FROM_VALUE[order]
    except KeyError:
        raise ValueError(f"unknown byte order {order!r}; expected one of {', '.join(WORD_ORDERS)}") from None


def _bytes_to_registers(value_bytes: bytes, order: str) -> tuple[int, int]:
    permutation = _check_order(order)
    wire = bytes(value_bytes[k] for k in permutation)
    return (wire[0] << 8) | wire[1], (wire[2] << 8) | wire[3]


def _registers_to_bytes(registers: Sequence[int], order: str) -> bytes:
    permutation = _check_order(order)
    if len(registers) != 2:
        raise ValueError(f"a 32-bit value needs exactly 2 registers, got {len(registers)}")
    for register in registers:
        if not is_integral_in(register, 0, 0xFFFF):
            raise ValueError(f"register value {register!r} is not a 16-bit unsigned integer")
    wire = bytes((int(registers[0]) >> 8, int(registers[0]) & 0xFF, int(registers[1]) >> 8, int(registers[1]) & 0xFF))
    value_bytes = bytearray(4)
    for position, k in enumerate(permutation):
        value_bytes[k] = wire[position]
    return bytes(value_bytes)


def encode_float32(value: float, order: WordOrder) -> tuple[int, int]:
    """Two registers holding ``value`` as an IEEE-754 float32.

    Parameters
    ----------
    value
        The number; it is rounded to the nearest float32 (NaN and infinities are encoded as such).
    order
        Byte order on the wire, one of :data:`WORD_ORDERS` (see the module table).

    Returns
    -------
    tuple[int, int]
        Register 0 and register 1, each 0..65535, in wire order.

    Raises
    ------
    ValueError
        Unknown order, or a finite value beyond the float32 range (about 3.4e38).

    Examples
    --------
    1.0 is ``0x3F800000`` in float32; ``"CDAB"`` sends the low word first:

    >>> encode_float32(1.0, "ABCD"), encode_float32(1.0, "CDAB")
    ((16256, 0), (0, 16256))
    >>> decode_float32((0, 16256), "CDAB")
    1.0
    """
    try:
        packed = struct.pack(">f", float(value))
    except OverflowError:
        raise ValueError(f"{value!r} is out of the float32 range") from None
    return _bytes_to_registers(packed, order)


def decode_float32(registers: Sequence[int], order: WordOrder) -> float:
    """The float32 held by two registers.

    Parameters
    ----------
    registers
        Register 0 and register 1 as read from the wire, each 0..65535.
    order
        Byte order on the wire, one of :data:`WORD_ORDERS`.

    Returns
    -------
    float
        The value (exactly representable in float32).

    Raises
    ------
    ValueError
        Unknown order, not exactly two registers, or a register outside 0..65535.
    """
    return float(struct.unpack(">f", _registers_to_bytes(registers, order))[0])


def encode_uint32(value: int, order: WordOrder) -> tuple[int, int]:
    """Two registers holding an unsigned 32-bit integer (0 .. 2**32 - 1); see :func:`encode_float32`."""
    if not is_integral_in(value, 0, 0xFFFFFFFF):
        raise ValueError(f"{value!r} is not an unsigned 32-bit integer")
    return _bytes_to_registers(int(value).to_bytes(4, "big"), order)


def decode_uint32(registers: Sequence[int], order: WordOrder) -> int:
    """The unsigned 32-bit integer held by two registers; see :func:`decode_float32`."""
    return int.from_bytes(_registers_to_bytes(registers, order), "big")


def encode_float32_array(values: ArrayLike, order: WordOrder) -> list[int]:
    """Registers for a vector of float32 values, two per value, in wire order.

    Parameters
    ----------
    values
        Shape (n,); each value is rounded to float32.
    order
        Byte order of every value, one of :data:`WORD_ORDERS`.

    Returns
    -------
    list[int]
        Length 2 n.
    """
    flat = np.asarray(values, dtype=np.float64)
    if flat.ndim != 1:
        raise ValueError(f"expected a 1-D vector, got shape {flat.shape}")
    registers: list[int] = []
    for value in flat:
        registers.extend(encode_float32(float(value), order))
    return registers


def decode_float32_array(registers: Sequence[int], order: WordOrder) -> NDArray[np.float64]:
    """The float32 values held by ``2 n`` registers, as float64 of shape (n,).

    Raises
    ------
    ValueError
        An odd number of registers, a register outside 0..65535 or an unknown order.
    """
    if len(registers) % 2:
        raise ValueError(f"float32 values need an even number of registers, got {len(registers)}")
    return np.array([decode_float32(registers[i:i + 2], order) for i in range(0, len(registers), 2)],
                    dtype=np.float64)


def round_to_float32(value: float) -> float:
    """``value`` rounded to the nearest float32, as a Python float.

    Raises
    ------
    ValueError
        A finite value beyond the float32 range.
    """
    try:
        return float(struct.unpack(">f", struct.pack(">f", float(value)))[0])
    except OverflowError:
        raise ValueError(f"{value!r} is out of the float32 range") from None
