"""The host's heartbeat and its ownership of the PLC, for :class:`~wavestack.drivers.plc.driver.PolishingLink`.

A PLC's watchdog stays alive only while *one* host beats: the PLC takes heartbeat, command and job
writes from one connection, its owner, until the watchdog trips (the register map's access model,
docs/instruments.md). With an owner block in the map every new connection of the link first
claims the PLC with the link's random 64-bit token, so the same host takes its place back after a
reconnect (a PLC restart, a socket closed after a lost reply) and no other peer can; then it reads
the PLC's heartbeat register and beats on from it. After a trip and an operator's re-arm nobody
owns the PLC: the first heartbeat is refused with exception 1, and the link claims again.

A monitor link (``wavestack plc status|rearm``) never claims and never beats; its re-arm is the
operator's, which the PLC takes from anyone.

A mixin of the link (it uses the link's lock, transport, map and write path).
"""

from __future__ import annotations

import logging
import secrets
import threading
from typing import TYPE_CHECKING

from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.plc.commands import CommandLedger
from wavestack.drivers.plc.gate import HeartbeatEchoStale, echo_lag_error
from wavestack.drivers.plc.register_map import RegisterMap
from wavestack.drivers.plc.status import PlcStatus
from wavestack.drivers.plc.transport import LinkTiming, ModbusTransport, PlcRefused, deadline_after

__all__ = ["HostHeartbeat", "new_token"]

_log = logging.getLogger(__name__)

_NOT_OWNER_EXCEPTION = 1


def new_token() -> list[int]:
    """A random 64-bit ownership token as four registers, none zero (the PLC refuses an all-zero token)."""
    return [secrets.randbits(16) | 1 for _ in range(4)]


class HostHeartbeat:
    """Heartbeat, ownership and re-arm; mixed into the link (module notes)."""

    _lock: threading.RLock
    _map: RegisterMap
    _device: str
    _monitor: bool
    _timing: LinkTiming
    _transport: ModbusTransport
    _ledger: CommandLedger
    _token: list[int]
    _beat: int
    _heartbeat_pending: bool
    _echo_stale: bool

    if TYPE_CHECKING:
        def _read_status(self, deadline: float) -> PlcStatus: ...
        def _write(self, address: int, values: list[int], function_code: int, deadline: float) -> None: ...

    def heartbeat(self, timeout_s: float) -> PlcStatus:
        """Increment the heartbeat register, then read the status and check the PLC echoes it.

        Call once per cycle, more often than the PLC's watchdog timeout.

        Raises
        ------
        PlcRefused
            Exception 4 when the watchdog has tripped (see :meth:`rearm`).
        HeartbeatEchoStale
            The echo trails the heartbeat by more than ``timing.heartbeat_echo_max_lag`` beats.
        """
        deadline = deadline_after(timeout_s)
        with self._lock:
            if self._monitor:
                raise ProtocolError(self._device, "a monitor link writes no heartbeat (the station owns it)")
            was_open = self._transport.ensure_connected(deadline)  # a new connection already beat once
            if was_open or self._heartbeat_pending:
                self._send_heartbeat(deadline)
            status = self._read_status(deadline)
            stale = self._echo_lag_error(status)
            self._echo_stale = stale is not None
            if stale is not None:
                try:
                    raise stale
                finally:  # no local naming the error: a cycle with this frame (the driver module's notes)
                    del stale
            return status

    def rearm(self, timeout_s: float) -> PlcStatus:
        """Write 1 to the re-arm register, resume the heartbeat (not on a monitor link) and return the status."""
        deadline = deadline_after(timeout_s)
        block = self._map.rearm
        with self._lock:
            self._transport.ensure_connected(deadline)
            self._ledger.invalidate()  # the watchdog zeroed the outputs: read them back before a command
            self._write(block.start, [1], block.write_function or 6, deadline)
            _log.warning("%s: watchdog re-armed by the host%s", self._device, " (monitor link)" if self._monitor else "")
            if not self._monitor:
                self._send_heartbeat(deadline)
            return self._read_status(deadline)

    def _echo_lag_error(self, status: PlcStatus) -> HeartbeatEchoStale | None:
        return echo_lag_error(self._device, self._beat, status, self._timing.heartbeat_echo_max_lag,
                              self._map.status.start + 2)

    def _resume_heartbeat(self, deadline: float) -> None:
        """First requests on a new connection: claim the PLC, continue from its heartbeat register and beat."""
        self._heartbeat_pending = True
        if self._monitor:
            return
        block = self._map.heartbeat
        try:
            self._claim(deadline)
            self._beat = self._transport.read(block.start, 1, block.read_function, deadline)[0]
            self._send_heartbeat(deadline)
        except PlcRefused as error:  # a tripped watchdog refuses everything but the re-arm; another owner
            _log.warning("%s: heartbeat not resumed after connecting: %s", self._device, error.detail)

    def _claim(self, deadline: float) -> None:
        """Write this link's token to the owner block (nothing without one); PlcRefused (1): another host owns."""
        if self._map.owner is not None:
            self._write(self._map.owner.start, list(self._token), self._map.owner.write_function or 16, deadline)

    def _send_heartbeat(self, deadline: float) -> None:
        block = self._map.heartbeat
        beat = (self._beat + 1) & 0xFFFF
        try:
            self._write(block.start, [beat], block.write_function or 6, deadline)
        except PlcRefused as error:  # not the owner (after a trip and re-arm nobody is): claim, then once more
            if error.exception_code != _NOT_OWNER_EXCEPTION or self._map.owner is None:
                raise
            self._claim(deadline)
            self._write(block.start, [beat], block.write_function or 6, deadline)
        self._beat = beat
        self._heartbeat_pending = False
