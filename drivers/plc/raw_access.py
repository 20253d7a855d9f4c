"""Raw register access of :class:`~wavestack.drivers.plc.driver.PolishingLink`, for commissioning.

A mixin: reads of any register, writes only inside the heartbeat or re-arm register (the allow-list
of :meth:`~wavestack.drivers.plc.register_map.RegisterMap.check_write`; the command and job blocks
are written only by their verbs, behind the readiness gate and the limits, the owner block only by
the link's claim). A monitor link writes the re-arm register only: the heartbeat is the station's.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING

from wavestack.drivers.plc.register_map import RegisterMap, WriteRefused, registers_fit
from wavestack.drivers.plc.transport import ModbusTransport, deadline_after

__all__ = ["RawAccess"]


class RawAccess:
    """Raw reads and allow-listed raw writes; mixed into the link."""

    _lock: threading.RLock
    _map: RegisterMap
    _device: str
    _transport: ModbusTransport
    _monitor: bool

    if TYPE_CHECKING:
        def _write(self, address: int, values: list[int], function_code: int, deadline: float) -> None: ...

    def read_registers(self, address: int, count: int, timeout_s: float) -> list[int]:
        """Raw read of ``count`` registers with the configured read function code (diagnostics)."""
        deadline = deadline_after(timeout_s)
        with self._lock:
            self._transport.ensure_connected(deadline)
            return self._transport.read(address, count, self._map.status.read_function, deadline)

    def write_registers(self, address: int, values: Sequence[int], timeout_s: float) -> None:
        """Raw write inside the heartbeat or re-arm register (commissioning); WriteRefused elsewhere, before the wire.

        The command and job blocks are refused too: they go through their verbs, the gate and the limits.
        """
        values = list(values)
        if not values or not registers_fit(values):
            raise ValueError(f"{self._device}: values must be 1..123 integers 0..65535, got {values!r}")
        block = self._map.check_write(address, len(values), self._write_function_for(address))
        if block.name in ("command", "job", "owner"):
            raise WriteRefused(self._device, f"refusing a raw write to register {address}: the {block.name} block "
                               "is written only by send_removal, the job verbs or the link's claim (the readiness "
                               "gate, the limits, the link's token)")
        if self._monitor and block.name != "rearm":
            raise WriteRefused(self._device, f"refusing a raw write to register {address}: a monitor link writes "
                               f"the re-arm register only (register {self._map.rearm.start}); the heartbeat is the "
                               "station's")
        deadline = deadline_after(timeout_s)
        with self._lock:
            self._transport.ensure_connected(deadline)
            self._write(address, values, block.write_function or 16, deadline)

    def _write_function_for(self, address: int) -> int:
        for block in self._map.blocks():
            if block.writable and block.contains(address):
                return block.write_function or 16
        return 16
