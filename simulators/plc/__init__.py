"""Simulated polishing-station PLC: a pymodbus 3.16 Modbus/TCP server and the machine it drives.

- :mod:`.server`: :class:`PlcSimulator`, the server thread (SimDevice/SimData), ground truth for tests.
- :mod:`.program`: the PLC's rules (watchdog, command handshake, status, outputs) and register layout.
- :mod:`.access`: which function code may reach which block; exception 1 or 2 for any other request.
- :mod:`.watchdog`: the heartbeat watchdog state machine.
- :mod:`.faults`: fault switches (drop, delay, truncate, corrupt replies; frozen echo; e-stop).
- :mod:`.polishing`: the polishing-station model a removal command acts on.
"""

from __future__ import annotations

from wavestack.simulators.plc.access import check_request, served_functions
from wavestack.simulators.plc.faults import SimFaults
from wavestack.simulators.plc.polishing import PolishingPass, PolishingStation, RemovalCommand
from wavestack.simulators.plc.program import PlcSimLayout, PolishingPlcProgram, SimOutputs
from wavestack.simulators.plc.server import PlcSimulator, RequestRecord
from wavestack.simulators.plc.watchdog import HeartbeatWatchdog, WatchdogState

__all__ = [
    "HeartbeatWatchdog",
    "PlcSimLayout",
    "PlcSimulator",
    "PolishingPass",
    "PolishingPlcProgram",
    "PolishingStation",
    "RemovalCommand",
    "RequestRecord",
    "SimFaults",
    "SimOutputs",
    "WatchdogState",
    "check_request",
    "served_functions",
]
