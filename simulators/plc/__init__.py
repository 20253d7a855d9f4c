"""Simulated polishing-station PLC: a pymodbus 3.16 Modbus/TCP server and the machine it drives.

- :mod:`.server`: :class:`PlcSimulator`, the server thread (SimDevice/SimData), ground truth for tests.
- :mod:`.program`: the PLC's rules (watchdog, command handshake, status, outputs) and register layout.
- :mod:`.access`: which function code may reach which block; exception 1 or 2 for any other request.
- :mod:`.watchdog`: the heartbeat watchdog state machine.
- :mod:`.faults`: fault switches (drop, delay, truncate, corrupt replies; frozen echo; e-stop).
- :mod:`.polishing`: the display model a removal command is shown on (it removes nothing).
- :mod:`.machine`: :class:`PolishingMachine`, which loads job files (:mod:`.job_file`, its own
  reader), checks them and polishes a :class:`RemovalTarget` point by point (:mod:`.machine_tif`);
  its job life as data in :mod:`.job_state`.
"""

from __future__ import annotations

from wavestack.simulators.plc.access import check_request, served_functions
from wavestack.simulators.plc.faults import SimFaults
from wavestack.simulators.plc.job_file import JobFileRefused, MachineJob, read_job_file, read_key_file
from wavestack.simulators.plc.job_state import JobEvent, JobState, StopReason, next_state
from wavestack.simulators.plc.machine import MachineSimSettings, MachineSnapshot, PolishingMachine, RemovalTarget
from wavestack.simulators.plc.machine_tif import GaussianTool
from wavestack.simulators.plc.polishing import PolishingPass, PolishingStation, RemovalCommand
from wavestack.simulators.plc.layout import PlcSimLayout
from wavestack.simulators.plc.program import PolishingPlcProgram, SimOutputs
from wavestack.simulators.plc.server import PlcSimulator, RequestRecord
from wavestack.simulators.plc.watchdog import HeartbeatWatchdog, WatchdogState

__all__ = [
    "GaussianTool",
    "HeartbeatWatchdog",
    "JobEvent",
    "JobFileRefused",
    "JobState",
    "MachineJob",
    "MachineSimSettings",
    "MachineSnapshot",
    "PolishingMachine",
    "RemovalTarget",
    "StopReason",
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
    "next_state",
    "read_job_file",
    "read_key_file",
    "served_functions",
]
