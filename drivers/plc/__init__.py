"""Modbus/TCP link to the polishing-station PLC (pymodbus 3.16).

- :mod:`.codec`: float32/uint32 in two registers, byte orders ABCD, CDAB, BADC, DCBA (pure).
- :mod:`.register_map`: the register map, the command block's layout and the write allow-list.
- :mod:`.status`: status word, acknowledge and machine outputs as frozen values.
- :mod:`.transport`: one pymodbus client with typed errors and capped reconnect back-off.
- :mod:`.commands`: command limits and the command the machine holds (pure bookkeeping).
- :mod:`.gate`: when the PLC may get a command (pure).
- :mod:`.driver`: :class:`PolishingLink`, heartbeat, command handshake, self-check, re-arm.
"""

from __future__ import annotations

from wavestack.drivers.plc.codec import (
    WORD_ORDERS,
    WordOrder,
    decode_float32,
    decode_float32_array,
    decode_uint32,
    encode_float32,
    encode_float32_array,
    encode_uint32,
    round_to_float32,
)
from wavestack.drivers.plc.commands import CommandLimits, CommandRefused
from wavestack.drivers.plc.driver import HeartbeatEchoStale, PlcNotReady, PolishingLink
from wavestack.drivers.plc.register_map import RegisterBlock, RegisterMap, WriteRefused
from wavestack.drivers.plc.status import CommandAck, MachineOutputs, PlcStatus, StatusBit, decode_outputs, decode_status
from wavestack.drivers.plc.transport import LinkTiming, PlcRefused

__all__ = [
    "WORD_ORDERS",
    "CommandAck",
    "CommandLimits",
    "CommandRefused",
    "HeartbeatEchoStale",
    "LinkTiming",
    "MachineOutputs",
    "PlcNotReady",
    "PlcRefused",
    "PlcStatus",
    "PolishingLink",
    "RegisterBlock",
    "RegisterMap",
    "StatusBit",
    "WordOrder",
    "WriteRefused",
    "decode_float32",
    "decode_float32_array",
    "decode_outputs",
    "decode_status",
    "decode_uint32",
    "encode_float32",
    "encode_float32_array",
    "encode_uint32",
    "round_to_float32",
]
