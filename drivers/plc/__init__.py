"""Modbus/TCP link to the polishing-station PLC (pymodbus 3.16).

- :mod:`.codec`: float32/uint32 in two registers, byte orders ABCD, CDAB, BADC, DCBA (pure).
- :mod:`.register_block`: one block of registers; :mod:`.register_map`: the register map, the
  command block's layout and the write allow-list.
- :mod:`.display`: the result display block (valid, residual RMS, PVr, spec verdict) and its codes (pure).
- :mod:`.status`: status word, acknowledge and machine outputs as frozen values.
- :mod:`.transport`: one pymodbus client with typed errors and capped reconnect back-off.
- :mod:`.commands`: command limits and the command the machine holds (pure bookkeeping).
- :mod:`.gate`: when the PLC may get a command (pure).
- :mod:`.jobs`: machine state, reason codes, job limits and the job-id ledger (pure).
- :mod:`.job_file`: the job file, written atomically with its CRC-32.
- :mod:`.job_control`: the link's job verbs (read the machine, load, start, abort).
- :mod:`.driver`: :class:`PolishingLink`, heartbeat, command handshake, self-check, re-arm.

The command block publishes the measured terms for the machine's display; removal happens only
through jobs.
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
from wavestack.drivers.plc.display import (LIMITING_QUANTITIES, ResultDisplay, SpecCode, decode_display, encode_display,
                                           invalid_display)
from wavestack.drivers.plc.driver import HeartbeatEchoStale, PlcNotReady, PolishingLink
from wavestack.drivers.plc.job_control import JobNotReady, JobRejected
from wavestack.drivers.plc.job_file import (JobFile, JobReceipt, encode_job_file, job_file_name, read_job_key,
                                            used_job_ids, write_job_file)
from wavestack.drivers.plc.jobs import (JobAction, JobLimits, JobReason, JobRefused, JobSummary, MachineState,
                                        MachineStatus, decode_machine)
from wavestack.drivers.plc.register_map import RegisterBlock, RegisterMap, WriteRefused
from wavestack.drivers.plc.status import CommandAck, MachineOutputs, PlcStatus, StatusBit, decode_outputs, decode_status
from wavestack.drivers.plc.transport import LinkTiming, PlcRefused

__all__ = [
    "LIMITING_QUANTITIES",
    "WORD_ORDERS",
    "CommandAck",
    "CommandLimits",
    "CommandRefused",
    "HeartbeatEchoStale",
    "JobAction",
    "JobFile",
    "JobLimits",
    "JobNotReady",
    "JobReason",
    "JobReceipt",
    "JobRefused",
    "JobRejected",
    "JobSummary",
    "MachineState",
    "MachineStatus",
    "LinkTiming",
    "MachineOutputs",
    "PlcNotReady",
    "PlcRefused",
    "PlcStatus",
    "PolishingLink",
    "RegisterBlock",
    "RegisterMap",
    "ResultDisplay",
    "SpecCode",
    "StatusBit",
    "WordOrder",
    "WriteRefused",
    "decode_float32",
    "decode_float32_array",
    "decode_display",
    "decode_machine",
    "decode_outputs",
    "decode_status",
    "decode_uint32",
    "encode_display",
    "encode_float32",
    "encode_float32_array",
    "encode_job_file",
    "encode_uint32",
    "invalid_display",
    "job_file_name",
    "round_to_float32",
    "used_job_ids",
    "read_job_key",
    "write_job_file",
]
