"""Simulated polishing-station PLC: a pymodbus 3.16 Modbus/TCP server built from SimDevice/SimData.

The server is a thin shell around :class:`~wavestack.simulators.plc.program.PolishingPlcProgram`
(the PLC's rules, re-implemented from the README's register map):

- one ``SimDevice`` with a block of registers; addresses outside the map answer exception 2, and so
  do writes to read-only blocks (self-check constant, status, outputs), through
  ``SimData(readonly=True)``;
- the server answers exactly as the register map says (:mod:`~wavestack.simulators.plc.access`): a
  function code the map never uses answers exception 1 when it is decoded, one the map uses for
  other registers (FC6 into the command block, a partial command write) exception 2;
- the device ``action`` runs the program for every request, with the number of the connection it
  came on (each connection's request handler sets it, :class:`_Connection`): ownership (exception 1
  for a write only the owner may make), watchdog (exception 4 when tripped), command handshake
  (exception 3 for refused parameters), status and outputs;
- at most ``max_connections`` connections at once (a real PLC's Modbus server has a fixed number
  too): a newcomer at the cap takes the place of the longest-quiet connection that does not own
  the PLC and has sent nothing for ``quiet_s``, else it is closed at once (counted,
  :attr:`PlcSimulator.connections_refused`), so silent strangers cannot lock the station out;
- :class:`SimFaults` switches: drop, truncate or corrupt replies through pymodbus's
  ``trace_packet`` hook (the request is still executed), delay replies in the action, freeze the
  heartbeat echo, press the e-stop; and :meth:`PlcSimulator.restart` for the server itself.

The server runs in its own thread with its own asyncio loop, bound to 127.0.0.1 on an ephemeral
port by default; :meth:`PlcSimulator.stop` closes every socket, cancels leftover tasks, closes the
loop and joins the thread.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import threading
import time
from collections import deque
from contextvars import ContextVar
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import TracebackType

from pymodbus.constants import ExcCodes
from pymodbus.pdu import ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import SimDevice

from wavestack.simulators.plc.access import check_request, refusing_request_classes
from wavestack.simulators.plc.faults import SimFaults
from wavestack.simulators.plc.machine import PolishingMachine
from wavestack.simulators.plc.polishing import PolishingStation
from wavestack.simulators.plc.layout import PlcSimLayout
from wavestack.simulators.plc.program import HISTORY_LENGTH, PolishingPlcProgram, SimOutputs
from wavestack.simulators.plc.watchdog import WatchdogState

__all__ = ["PlcSimulator", "RequestRecord"]

_log = logging.getLogger(__name__)

#: The connection a request came on, set by its handler's task for the program's action.
_CONNECTION: ContextVar[int] = ContextVar("plc_connection", default=0)
#: Connections served at once, and how long a connection must have been quiet to make room.
MAX_CONNECTIONS, QUIET_S = 8, 10.0


class _Connection(ServerRequestHandler):
    """pymodbus's handler of one connection, which tells the program which connection a request is from."""

    def __init__(self, server: _Server, number: int, on_close: Callable[[int], None]) -> None:
        self.number = number
        self.last_heard = time.monotonic()
        self._on_close = on_close
        self._admit = server.admit
        trace_connect = server.trace_connect

        def traced(connected: bool) -> None:
            if trace_connect is not None:
                trace_connect(connected)
            if not connected:
                on_close(number)
        super().__init__(server, server.trace_packet, server.trace_pdu, traced)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        self._admit(self)

    def callback_data(self, data: bytes, addr: tuple | None = None) -> int:
        self.last_heard = time.monotonic()
        return super().callback_data(data, addr)

    def drop(self) -> None:
        """Close this connection from the server's side."""
        self.close()
        self._on_close(self.number)

    async def handle_request(self) -> None:
        token = _CONNECTION.set(self.number)  # each request runs in a task of its own: the value is its own
        try:
            await super().handle_request()
        finally:
            _CONNECTION.reset(token)


class _Server(ModbusTcpServer):
    """``ModbusTcpServer`` whose connections are numbered (:class:`_Connection`)."""

    def __init__(self, *args: object, numbers: Iterator[int], on_close: Callable[[int], None],
                 owner: Callable[[], int | None], on_refused: Callable[[], None], max_connections: int,
                 quiet_s: float, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._numbers = numbers
        self._on_close = on_close
        self._owner, self._on_refused = owner, on_refused
        self._max_connections, self._quiet_s = max_connections, quiet_s

    def callback_new_connection(self) -> _Connection:
        return _Connection(self, next(self._numbers), self._on_close)

    def admit(self, newcomer: _Connection) -> None:
        """Keep ``newcomer`` within the cap, making room from a quiet stranger, or close it (module notes)."""
        others = [c for c in self.active_connections.values() if c is not newcomer and isinstance(c, _Connection)]
        if len(others) < self._max_connections:
            return
        now, owner = time.monotonic(), self._owner()
        quiet = [c for c in others if c.number != owner and now - c.last_heard >= self._quiet_s]
        if quiet:
            oldest = min(quiet, key=lambda c: c.last_heard)
            _log.warning("PLC simulator: %d connections; connection %d, quiet %.0f s, closed for a new one",
                         len(others), oldest.number, now - oldest.last_heard)
            oldest.drop()
            return
        _log.warning("PLC simulator: %d connections, none quiet: a new connection refused", len(others))
        self._on_refused()
        newcomer.drop()


@dataclass(frozen=True)
class RequestRecord:
    """One request the server decoded: function code, first register, count, written values."""

    function_code: int
    address: int
    count: int
    values: tuple[int, ...]


class PlcSimulator:
    """The simulated PLC, serving Modbus/TCP from a background thread.

    Parameters
    ----------
    layout
        Register layout and watchdog timeout.
    station
        The polishing model the commands act on (ground truth for tests: :attr:`station`).
    host, port
        Where to listen; port 0 picks a free port (see :attr:`port`).
    clock
        Monotonic clock in seconds (tests may pass their own).
    machine
        The polishing machine the job block drives (None: no jobs); :meth:`stop` stops its run.
    max_connections, quiet_s
        Connections served at once; how long one must have sent nothing to make room for a newcomer.

    Attributes
    ----------
    faults
        The fault switches (:class:`SimFaults`), live while serving.
    program
        The PLC's rules and state (ground truth; the properties below read it at the current time).
    station
        The polishing model (ground truth of the surface).

    Use it as a context manager, or call :meth:`start` and :meth:`stop`.
    """

    def __init__(self, layout: PlcSimLayout, station: PolishingStation, *, host: str = "127.0.0.1",
                 port: int = 0, clock: Callable[[], float] = time.monotonic,
                 machine: PolishingMachine | None = None, max_connections: int = MAX_CONNECTIONS,
                 quiet_s: float = QUIET_S) -> None:
        if machine is not None and not layout.has_jobs:
            raise ValueError("a PLC simulator with a machine needs job_register and machine_register in its layout")
        self.faults = SimFaults()
        self.program = PolishingPlcProgram(layout, station, self.faults, machine)
        self.machine = machine
        if machine is not None:
            machine.attach_interlock(lambda: self.program.interlock(self._clock()))
        self.layout = layout
        self.station = station
        self._host = host
        self._port = port
        self._clock = clock
        self._lock = threading.Lock()
        self._requests: deque[RequestRecord] = deque(maxlen=HISTORY_LENGTH)  # bounded: a soak must not grow
        self._request_count = 0
        self._connections = self._refused = 0
        self._max_connections, self._quiet_s = max_connections, quiet_s
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: _Server | None = None
        self._numbering = itertools.count(1)  # runs on across restarts: a new connection is never an old one
        self._stopping: asyncio.Event | None = None
        self._ready = threading.Event()
        self._startup_error: BaseException | None = None
        self._device = SimDevice(id=layout.unit_id, simdata=layout.simdata(), action=self._action)

    # ----------------------------------------------------------------------------- lifecycle
    @property
    def host(self) -> str:
        """The address the server is bound to."""
        return self._host

    @property
    def port(self) -> int:
        """The TCP port the server listens on (the real one once started, also after restarts)."""
        return self._port

    def start(self, timeout_s: float = 5.0) -> PlcSimulator:
        """Start serving in a background thread; returns once listening."""
        if self._thread is not None:
            raise RuntimeError("the PLC simulator is already running")
        self._ready.clear()
        self._startup_error = None
        self._thread = threading.Thread(target=self._run, name=f"plc-simulator-{self._host}", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            self.stop()
            raise TimeoutError(f"PLC simulator did not start listening within {timeout_s} s")
        if self._startup_error is not None:
            error = self._startup_error
            self.stop()
            raise OSError(f"PLC simulator cannot listen on {self._host}:{self._port}: {error}") from error
        _log.info("PLC simulator listening on %s:%d", self._host, self._port)
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Close every connection and the listener, end the loop and join the thread; idempotent."""
        thread, loop = self._thread, self._loop
        if thread is None:
            return
        if loop is not None and self._stopping is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(self._stopping.set)
            except RuntimeError:  # the loop closed meanwhile
                pass
        thread.join(timeout_s)
        if thread.is_alive():
            raise TimeoutError(f"PLC simulator thread did not stop within {timeout_s} s")
        self._thread = None
        if self.machine is not None:
            self.machine.close(timeout_s)

    def restart(self, downtime_s: float = 0.0, timeout_s: float = 5.0, *, power_cycle: bool = False) -> None:
        """Drop every connection and close the listener; listen again on the same port after ``downtime_s``.

        Returns once the listener is closed; the PLC's memory and state are kept (a restart of the
        Modbus service, not a power cycle). Connection attempts during the downtime are refused.
        With ``power_cycle`` the PLC program restarts too: a running job stops (ABORTED,
        PLC_RESTART, removal so far kept), the watchdog waits for a heartbeat change, outputs are
        zero; the machine keeps its log of used job ids (retentive memory).
        """
        loop = self._loop
        if loop is None or self._thread is None:
            raise RuntimeError("the PLC simulator is not running")
        if power_cycle:
            self.program.power_cycle(self._clock())
        asyncio.run_coroutine_threadsafe(self._restart(downtime_s), loop).result(timeout_s)

    def wait_listening(self, timeout_s: float) -> bool:
        """Wait until the server listens (after a restart); True if it does."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self._server is not None:
                return True
            time.sleep(0.01)
        return self._server is not None

    def __enter__(self) -> PlcSimulator:
        return self.start()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.stop()

    # ----------------------------------------------------------------------------- ground truth
    @property
    def watchdog_state(self) -> WatchdogState:
        """The watchdog's state now."""
        return self.program.watchdog_state(self._clock())

    @property
    def watchdog_trips(self) -> int:
        """How many times the watchdog tripped."""
        return self.program.watchdog_trips(self._clock())

    @property
    def outputs(self) -> SimOutputs:
        """The machine outputs now."""
        return self.program.outputs(self._clock())

    @property
    def last_accepted_id(self) -> int:
        """Id of the last accepted command (0 = none)."""
        return self.program.last_accepted_id

    @property
    def accepted_commands(self) -> list[int]:
        """Ids of the commands that took effect, in order (the last ``HISTORY_LENGTH``, see :mod:`.program`)."""
        return self.program.accepted_commands

    @property
    def heartbeat_value(self) -> int:
        """The last heartbeat value the PLC saw."""
        return self.program.heartbeat_value

    @property
    def requests(self) -> list[RequestRecord]:
        """The requests decoded so far (the last ``HISTORY_LENGTH`` = 10000; :attr:`request_count` counts all)."""
        with self._lock:
            return list(self._requests)

    @property
    def request_count(self) -> int:
        """Requests decoded since start."""
        with self._lock:
            return self._request_count

    @property
    def connections(self) -> int:
        """TCP connections accepted since start."""
        with self._lock:
            return self._connections

    @property
    def connections_refused(self) -> int:
        """Connections closed on arrival because the cap was full of connections that were not quiet."""
        with self._lock:
            return self._refused

    def _count_refused(self) -> None:
        with self._lock:
            self._refused += 1

    # ----------------------------------------------------------------------------- the loop thread
    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve())
        finally:
            pending = [task for task in asyncio.all_tasks(loop) if not task.done()]
            for task in pending:
                task.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()
            self._loop = None
            self._ready.set()

    async def _serve(self) -> None:
        self._stopping = asyncio.Event()
        try:
            await self._open()
        except (OSError, RuntimeError) as error:
            self._startup_error = error
            return
        finally:
            self._ready.set()
        await self._stopping.wait()
        await self._close()

    async def _open(self) -> None:
        server = _Server(self._device, address=(self._host, self._port), trace_packet=self._trace_packet,
                         trace_pdu=self._trace_pdu, trace_connect=self._trace_connect,
                         custom_pdu=refusing_request_classes(self.layout), numbers=self._numbering,
                         on_close=self.program.connection_closed, owner=lambda: self.program.owner_connection,
                         on_refused=self._count_refused, max_connections=self._max_connections,
                         quiet_s=self._quiet_s)
        await server.serve_forever(background=True)
        self._server = server
        sockets = getattr(server.transport, "sockets", None) or ()
        if sockets:
            self._port = int(sockets[0].getsockname()[1])

    async def _close(self) -> None:
        server, self._server = self._server, None
        if server is not None:
            await server.shutdown()
        for _ in range(3):  # let the transports run their connection_lost callbacks and close the sockets
            await asyncio.sleep(0)

    async def _restart(self, downtime_s: float) -> None:
        await self._close()
        _log.warning("PLC simulator: server restarted (downtime %.3f s)", downtime_s)
        if downtime_s <= 0:
            await self._open()
        else:
            asyncio.get_running_loop().create_task(self._reopen_after(downtime_s))

    async def _reopen_after(self, downtime_s: float) -> None:
        await asyncio.sleep(downtime_s)
        try:
            await self._open()
        except (OSError, RuntimeError) as error:
            _log.error("PLC simulator: cannot listen again on %s:%d after a restart: %s", self._host, self._port, error)

    # ----------------------------------------------------------------------------- pymodbus hooks
    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending or len(data) < 8:
            return data
        return self.faults.apply_to_reply(data)

    def _trace_pdu(self, sending: bool, pdu: ModbusPDU) -> ModbusPDU:
        if not sending:
            values = tuple(int(v) for v in getattr(pdu, "registers", []) or [])
            count = int(getattr(pdu, "count", 0) or len(values))
            with self._lock:
                self._requests.append(RequestRecord(int(pdu.function_code), int(getattr(pdu, "address", 0)),
                                                    count, values))
                self._request_count += 1
        return pdu

    def _trace_connect(self, connected: bool) -> None:
        if connected:
            with self._lock:
                self._connections += 1

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None) -> ExcCodes | None:
        delay_s = self.faults.delay_s
        if delay_s > 0:
            await asyncio.sleep(delay_s)
        refusal = check_request(self.layout, function_code, address, count, writing=set_values is not None)
        if refusal is not None:
            return refusal
        written = [int(v) for v in set_values] if set_values is not None else None
        return self.program.on_request(address, written, self._clock(), start_address, registers, _CONNECTION.get())
