"""One Modbus/TCP connection (pymodbus 3.16 sync client) with typed errors and capped back-off.

:class:`ModbusTransport` turns pymodbus's outcomes into :mod:`wavestack.drivers.errors`, each naming
the device, the function code and the register:

- no byte of a reply within the timeout -> :class:`DeviceTimeout`;
- connection refused, reset or closed by the peer -> :class:`DeviceDisconnected`, at once;
- some bytes that do not form the expected reply (truncated, undecodable, wrong function code,
  wrong register count or echo) -> :class:`ProtocolError`;
- a Modbus exception reply -> :class:`PlcRefused` (a :class:`ProtocolError`) with its code.

After a timeout or a malformed reply the socket is closed, so late or partial bytes can never be
taken for the next reply; the next request opens a fresh connection. Failed connection attempts
are spaced by an exponential back-off (initial, doubled per failure, capped); a call whose deadline
falls before the next allowed attempt fails at once instead of sleeping past its timeout. Every new
connection first runs the ``on_connect`` callback (the link's heartbeat).

pymodbus's own retries are off (``retries=0``): retrying is a decision of the layer that knows
whether a request is idempotent.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.pdu import ExceptionResponse, ModbusPDU

from wavestack.drivers.errors import DeviceDisconnected, DeviceTimeout, ProtocolError

__all__ = ["LinkTiming", "ModbusTransport", "PlcRefused", "deadline_after"]

_log = logging.getLogger(__name__)

_EXCEPTION_MEANING = {
    1: "illegal function, or not for this connection: another host owns the PLC",
    2: "illegal data address (not in the PLC's map, or read-only)",
    3: "illegal data value (a parameter out of range)",
    4: "server device failure (watchdog tripped: re-arm; or e-stop; or no heartbeat seen yet)",
    5: "acknowledge",
    6: "server device busy",
}


class PlcRefused(ProtocolError):
    """The PLC answered with a Modbus exception response.

    Attributes
    ----------
    exception_code
        The Modbus exception code (2 illegal address, 3 illegal value, 4 device failure, 6 busy).
    function_code, address
        The request that was refused.
    """

    def __init__(self, device: str, function_code: int, address: int, exception_code: int) -> None:
        meaning = _EXCEPTION_MEANING.get(exception_code, "unknown exception")
        super().__init__(device, f"exception {exception_code} ({meaning}) to FC{function_code} at register "
                                 f"{address}; expected a normal reply")
        self.exception_code = exception_code
        self.function_code = function_code
        self.address = address


@dataclass(frozen=True)
class LinkTiming:
    """Timing and retry policy of a PLC link.

    Attributes
    ----------
    io_timeout_s
        Longest wait for one reply or one connection attempt, s (a call's own ``timeout_s`` may
        shorten it).
    reconnect_initial_s, reconnect_max_s
        Back-off between failed connection attempts: the initial value, doubled after each failure,
        capped at the maximum, s. A successful connection resets it.
    command_retries
        Extra sends of a command after a timeout or malformed reply (same id, so idempotent).
    heartbeat_echo_max_lag
        Beats the PLC's heartbeat echo may trail the host's heartbeat.
    """

    io_timeout_s: float = 0.5
    reconnect_initial_s: float = 0.05
    reconnect_max_s: float = 0.5
    command_retries: int = 2
    heartbeat_echo_max_lag: int = 2

    def __post_init__(self) -> None:
        if not (self.io_timeout_s > 0 and 0 < self.reconnect_initial_s <= self.reconnect_max_s):
            raise ValueError(f"invalid link timing {self}: need io_timeout_s > 0 and "
                             "0 < reconnect_initial_s <= reconnect_max_s")
        if self.command_retries < 0 or self.heartbeat_echo_max_lag < 0:
            raise ValueError(f"invalid link timing {self}: retries and lag must be >= 0")


def deadline_after(timeout_s: float) -> float:
    """``time.monotonic()`` deadline for a call's timeout; ValueError unless ``timeout_s > 0``."""
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
    return time.monotonic() + timeout_s


class ModbusTransport:
    """A pymodbus ``ModbusTcpClient`` wrapped in typed errors and capped back-off.

    Parameters
    ----------
    host, port
        The Modbus/TCP server.
    unit_id
        Unit id sent with every request.
    device
        How errors name the device.
    timing
        Timeouts and back-off.
    on_connect
        Called with the call's deadline right after each new connection, before the request that
        needed it (the link sends its heartbeat there).
    """

    def __init__(self, host: str, port: int, unit_id: int, device: str, timing: LinkTiming,
                 on_connect: Callable[[float], None]) -> None:
        self._host, self._port, self._unit_id = host, port, unit_id
        self._device = device
        self._timing = timing
        self._on_connect = on_connect
        self._client = ModbusTcpClient(host, port=port, timeout=timing.io_timeout_s, retries=0,
                                       name=f"plc-{host}:{port}", trace_packet=self._trace_packet)
        self._rx_bytes = 0
        self._backoff_s = 0.0
        self._next_attempt = 0.0
        self._ever_connected = False
        self.reconnects = 0  #: connections opened after the first one

    @property
    def connected(self) -> bool:
        """Whether a TCP connection is open."""
        return bool(self._client.connected)

    def close(self) -> None:
        """Close the socket; idempotent. The next request reconnects."""
        self._client.close()

    def reset_backoff(self) -> None:
        """Allow a connection attempt at once."""
        self._backoff_s = 0.0
        self._next_attempt = 0.0

    def ensure_connected(self, deadline: float) -> bool:
        """Connect if needed (then run ``on_connect``); True if the connection was already open.

        Raises
        ------
        DeviceDisconnected
            No connection before ``deadline``, or the next attempt allowed by the back-off falls
            after it.
        """
        if self._client.connected:
            return True
        while True:
            now = time.monotonic()
            if self._next_attempt > now:
                if self._next_attempt >= deadline:
                    raise DeviceDisconnected(self._device, f"not connected; next reconnect attempt in "
                                             f"{self._next_attempt - now:.2f} s (back-off), after this call's timeout")
                time.sleep(self._next_attempt - now)
            self._client.comm_params.timeout_connect = self._reply_timeout(deadline)
            if self._client.connect():
                break
            self._backoff_s = min(max(2 * self._backoff_s, self._timing.reconnect_initial_s),
                                  self._timing.reconnect_max_s)
            self._next_attempt = time.monotonic() + self._backoff_s
            if self._next_attempt >= deadline:
                raise DeviceDisconnected(self._device, f"cannot connect to {self._host}:{self._port} (refused or "
                                         f"unreachable), expected a Modbus/TCP server; next attempt in "
                                         f"{self._backoff_s:.2f} s")
        self.reset_backoff()
        if self._ever_connected:
            self.reconnects += 1
            _log.warning("%s: reconnected", self._device)
        self._ever_connected = True
        self._on_connect(deadline)
        return False

    def read(self, address: int, count: int, function_code: int, deadline: float) -> list[int]:
        """Read ``count`` registers with FC3 (holding) or FC4 (input); checks the reply's count."""
        if function_code == 4:
            reply = self._execute(4, address, deadline, lambda: self._client.read_input_registers(
                address, count=count, device_id=self._unit_id))
        else:
            reply = self._execute(3, address, deadline, lambda: self._client.read_holding_registers(
                address, count=count, device_id=self._unit_id))
        registers = [int(r) for r in getattr(reply, "registers", [])]
        if len(registers) != count:
            self._malformed(function_code, address, f"{len(registers)} registers, expected {count}")
        return registers

    def write(self, address: int, values: list[int], function_code: int, deadline: float) -> None:
        """Write with FC6 (one register) or FC16; checks the reply's echo.

        The caller is responsible for the allow-list; this layer writes what it is given.
        """
        if function_code == 6:
            reply = self._execute(6, address, deadline, lambda: self._client.write_register(
                address, values[0], device_id=self._unit_id))
            echoed: tuple[object, object] = (getattr(reply, "address", None), list(getattr(reply, "registers", [])))
            expected: tuple[object, object] = (address, values)
        else:
            reply = self._execute(16, address, deadline, lambda: self._client.write_registers(
                address, values, device_id=self._unit_id))
            echoed = (getattr(reply, "address", None), getattr(reply, "count", None))
            expected = (address, len(values))
        if echoed != expected:
            self._malformed(function_code, address, f"echoed (address, value) {echoed}, expected {expected}")

    # ----------------------------------------------------------------------------- internals
    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            self._rx_bytes = max(self._rx_bytes, len(data))
        return data

    def _reply_timeout(self, deadline: float) -> float:
        """The wait for one reply: the I/O timeout cut to the call's remaining budget (at least 1 ms)."""
        return max(min(self._timing.io_timeout_s, deadline - time.monotonic()), 0.001)

    def _malformed(self, function_code: int, address: int, what: str) -> None:
        self._client.close()
        raise ProtocolError(self._device, f"malformed reply to FC{function_code} at register {address}: {what}")

    def _execute(self, function_code: int, address: int, deadline: float,
                 request: Callable[[], ModbusPDU]) -> ModbusPDU:
        where = f"FC{function_code} at register {address} (unit {self._unit_id})"
        if not self._client.connected:
            raise DeviceDisconnected(self._device, f"connection lost before {where}")
        timeout = self._reply_timeout(deadline)
        self._client.comm_params.timeout_connect = timeout
        self._rx_bytes = 0
        try:
            reply = request()
        except ConnectionException as error:
            self._client.close()
            raise DeviceDisconnected(self._device, f"connection lost during {where} ({error})") from None
        except ModbusIOException:
            self._client.close()
            if self._rx_bytes:
                raise ProtocolError(self._device, f"truncated or malformed reply to {where}: {self._rx_bytes} "
                                    "bytes that do not form the expected frame") from None
            raise DeviceTimeout(self._device, f"no reply to {where} within {timeout:.3f} s") from None
        except OSError as error:
            self._client.close()
            raise DeviceDisconnected(self._device, f"I/O error during {where} ({error})") from None
        except ModbusException as error:
            self._client.close()
            raise ProtocolError(self._device, f"bad exchange during {where} ({error})") from None
        if isinstance(reply, ExceptionResponse):
            raise PlcRefused(self._device, function_code, address, int(reply.exception_code))
        if getattr(reply, "function_code", None) != function_code:
            self._malformed(function_code, address, f"function code {getattr(reply, 'function_code', None)}")
        return reply
