"""Which Modbus request the simulated PLC's register map allows, and the exception for any other.

Re-implemented from the register map in the README and ``config/plc-*.toml`` (not from the driver's
map): every block is read with one function code (``read_function``, 3 or 4); the heartbeat and the
re-arm register are written alone with ``single_write_function`` (6, or 16 with one register); the
command block, the job block, the owner block and the display block only whole, each in one FC16
request; nothing else is written. Which *connection* may write is :mod:`.ownership`'s rule.

Which exception (Modbus Application Protocol Specification v1.1b3, section 7, and the transaction
state diagram of section 4.4, where the function code is checked before the address):

* **1 (illegal function)** for a function code the map never uses, at any address: this PLC does not
  serve it at all. That covers FC4 on a map read with FC3 (it has no input-register table; and FC3 on
  a map read with FC4), FC6 on a map whose single writes are FC16, coils and discrete inputs (1, 2,
  5, 15), mask write (22), read/write multiple (23) and the file and FIFO functions (20, 21, 24). They
  are refused when the request is decoded (:func:`refusing_request_classes`), before any address is
  looked at, as the state diagram has it.
* **2 (illegal data address)** for a function code the map uses, aimed at registers the map does not
  allow it for: FC6 into the command block, FC16 onto the heartbeat of an FC6 map, two single
  registers in one FC16, and a command write that covers only part of the block (the block must be
  written in one request, or a new id would start a command from stale registers). Writes to
  read-only blocks and to addresses outside the map answer 2 already (pymodbus's ``SimData``).
"""

from __future__ import annotations

from pymodbus.constants import ExcCodes
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU

from wavestack.simulators.plc.layout import DISPLAY_COUNT, JOB_COUNT, OWNER_COUNT, PlcSimLayout

__all__ = ["COMMAND_WRITE_FUNCTION", "DATA_FUNCTIONS", "check_request", "refusing_request_classes",
           "served_functions"]

#: The command block is written with FC16, in one request.
COMMAND_WRITE_FUNCTION = 16
#: Function codes that read or write data (bits, registers, files, FIFO).
DATA_FUNCTIONS = (1, 2, 3, 4, 5, 6, 15, 16, 20, 21, 22, 23, 24)


def served_functions(layout: PlcSimLayout) -> frozenset[int]:
    """The function codes the map uses: its read code, its single-write code and FC16."""
    return frozenset({layout.read_function, layout.single_write_function, COMMAND_WRITE_FUNCTION})


def check_request(layout: PlcSimLayout, function_code: int, address: int, count: int,
                  writing: bool) -> ExcCodes | None:
    """The exception the map demands for one register access, or None when it is allowed.

    Parameters
    ----------
    layout
        The register map.
    function_code, address, count
        The request (0-based protocol address, number of registers).
    writing
        True for the write of a write request; False for a read, including the read-back pymodbus
        makes after a write that passed, to build the echo (it carries the write's function code).
    """
    if function_code not in served_functions(layout):
        return ExcCodes.ILLEGAL_FUNCTION
    if not writing:
        return None
    start, size = layout.command_block
    allowed = ((layout.heartbeat_register, 1, layout.single_write_function),
               (layout.rearm_register, 1, layout.single_write_function),
               (start, size, COMMAND_WRITE_FUNCTION), (layout.job_register, JOB_COUNT, COMMAND_WRITE_FUNCTION),
               (layout.owner_register, OWNER_COUNT, COMMAND_WRITE_FUNCTION),
               (layout.display_register, DISPLAY_COUNT, COMMAND_WRITE_FUNCTION))
    if (address, count, function_code) in allowed:
        return None
    return ExcCodes.ILLEGAL_ADDRESS


def refusing_request_classes(layout: PlcSimLayout) -> list[type[ModbusPDU]]:
    """Request classes for the data functions the map does not use; each answers exception 1.

    For ``ModbusTcpServer(custom_pdu=...)``: they decode the request as pymodbus's own class does (so
    the request is still traced), then refuse it without touching the register memory.
    """
    refused = [code for code in DATA_FUNCTIONS if code not in served_functions(layout)]
    return [type(f"Refused{DecodePDU.pdu_table[code][0].__name__}", (DecodePDU.pdu_table[code][0],),
                 {"datastore_update": _refuse}) for code in refused]


async def _refuse(self: ModbusPDU, context: object, device_id: int) -> ModbusPDU:
    return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_FUNCTION)
