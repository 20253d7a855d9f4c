"""The simulated controller on TCP, as a C-887 serves GCS on its Ethernet port (PI's default: 50000).

One thread runs a ``selectors`` loop over the listening socket, every client connection and a wake-up
socket pair: it reads whatever bytes arrive (several commands in one packet, one command over
several packets: :class:`~wavestack.simulators.pi_gcs.framing.LineAssembler` does not care), feeds
them to the :class:`~wavestack.simulators.pi_gcs.controller.GcsController` and writes the answers,
honouring split replies (pieces released at their times) and dropped connections. All clients share
the one controller (one error state, one platform), as on the real device. Sockets never block the
loop: a reply goes out as far as the peer's buffer takes it and the rest waits for the socket to be
writable, so a client that never reads stalls no one; one whose unsent replies pass
``MAX_PENDING_BYTES`` is disconnected. At most ``max_clients`` connections are served at once: a
newcomer at the cap takes the place of the longest-quiet client that has sent nothing for
``quiet_s``, else it is closed on arrival (counted in :attr:`HexapodSimulator.refused`), so silent
peers cannot lock the station out and busy ones keep their places.

:meth:`HexapodSimulator.stop` wakes the loop, which closes every socket before the thread ends; the
caller joins the thread, so nothing outlives the ``with`` block.
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType

from wavestack.simulators.pi_gcs.controller import GcsController
from wavestack.simulators.pi_gcs.faults import GcsSimFaults
from wavestack.simulators.pi_gcs.framing import LineAssembler
from wavestack.simulators.pi_gcs.pose import SimPose
from wavestack.simulators.pi_gcs.settings import HexapodSimSettings

__all__ = ["DEFAULT_GCS_PORT", "MAX_CLIENTS", "MAX_PENDING_BYTES", "QUIET_S", "HexapodSimulator"]

_log = logging.getLogger(__name__)

#: PI's TCP port for GCS on its controllers.
DEFAULT_GCS_PORT = 50000
_IDLE_S = 0.1  # longest sleep of the loop when nothing is due
#: Unsent reply bytes a client may leave waiting before it is disconnected (a GCS reply is a few
#: hundred bytes: a client this far behind does not read).
MAX_PENDING_BYTES = 1 << 16
#: Connections served at once, and how long a client must have been quiet to make room for a newcomer.
MAX_CLIENTS, QUIET_S = 8, 30.0


@dataclass
class _Client:
    sock: socket.socket
    assembler: LineAssembler = field(default_factory=LineAssembler)
    outbox: deque[tuple[float, bytes]] = field(default_factory=deque)  # (monotonic due time, chunk)
    close_when_sent: bool = False
    last_due: float = 0.0
    blocked: bool = False  # the socket's buffer is full: wait until it is writable
    pending: int = 0  # bytes in the outbox
    last_heard: float = field(default_factory=time.monotonic)  # when it last sent a byte


class HexapodSimulator:
    """A simulated PI GCS 2.0 controller serving TCP from a background thread.

    Parameters
    ----------
    settings
        Axes, limits, velocity, pivot, identity (the hexapod by default; two axes for the field stage).
    host, port
        Where to listen; port 0 picks a free port (see :attr:`port`).
    clock
        Simulated-time clock, s (tests pass one they advance by hand).
    max_clients, quiet_s
        Connections served at once; how long one must have sent nothing to make room (module notes).

    Attributes
    ----------
    controller
        The device model (ground truth for tests).
    faults
        Its fault switches.

    Examples
    --------
    >>> import socket
    >>> with HexapodSimulator(HexapodSimSettings()) as sim:
    ...     with socket.create_connection(("127.0.0.1", sim.port), timeout=5.0) as link:
    ...         link.sendall(b"CSV?\\n")
    ...         link.recv(64)
    b'2.0\\n'
    """

    def __init__(self, settings: HexapodSimSettings | None = None, *, host: str = "127.0.0.1", port: int = 0,
                 clock: Callable[[], float] = time.monotonic, max_clients: int = MAX_CLIENTS,
                 quiet_s: float = QUIET_S) -> None:
        self._max_clients, self._quiet_s = max_clients, quiet_s
        self.refused = 0
        self.controller = GcsController(settings or HexapodSimSettings(), clock=clock)
        self.faults: GcsSimFaults = self.controller.faults
        self._host, self._port = host, port
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._wake_r: socket.socket | None = None
        self._wake_w: socket.socket | None = None
        self._listener: socket.socket | None = None
        self._clients_lock = threading.Lock()
        self._clients: dict[int, _Client] = {}
        self._drop_all = threading.Event()
        self.connections = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def host(self) -> str:
        """The address the server is bound to."""
        return self._host

    @property
    def port(self) -> int:
        """The TCP port the server listens on (the real one once started)."""
        return self._port

    @property
    def pose(self) -> SimPose:
        """Every axis's position now (thread-safe snapshot)."""
        return self.controller.pose

    def start(self) -> HexapodSimulator:
        """Bind, listen and serve in a background thread; returns once listening."""
        if self._thread is not None:
            raise RuntimeError("the GCS simulator is already running")
        listener = socket.create_server((self._host, self._port), family=_family(self._host), backlog=8)
        listener.setblocking(False)
        self._listener = listener
        self._port = int(listener.getsockname()[1])
        self._wake_r, self._wake_w = socket.socketpair()
        self._stopping.clear()
        self._thread = threading.Thread(target=self._serve, name=f"gcs-simulator-{self._port}", daemon=True)
        self._thread.start()
        _log.info("GCS simulator listening on %s:%d", self._host, self._port)
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Close every connection and the listener and join the thread; idempotent."""
        thread = self._thread
        if thread is None:
            return
        self._stopping.set()
        self._wake()
        thread.join(timeout_s)
        if thread.is_alive():
            raise TimeoutError(f"GCS simulator thread did not stop within {timeout_s} s")
        self._thread = None
        for sock in (self._wake_r, self._wake_w):
            if sock is not None:
                sock.close()
        self._wake_r = self._wake_w = None

    def disconnect_clients(self) -> None:
        """Close every client connection now (the cable pulled); the listener keeps accepting."""
        self._drop_all.set()
        self._wake()

    @property
    def client_count(self) -> int:
        """Client connections open now."""
        with self._clients_lock:
            return len(self._clients)

    def __enter__(self) -> HexapodSimulator:
        return self.start()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.stop()

    # ------------------------------------------------------------------ the loop thread
    def _wake(self) -> None:
        try:
            if self._wake_w is not None:
                self._wake_w.send(b"\0")
        except OSError:  # the buffer is full (a wake-up is pending anyway) or the pair is closing
            pass

    def _serve(self) -> None:
        selector = selectors.DefaultSelector()
        listener, wake = self._listener, self._wake_r
        assert listener is not None and wake is not None
        selector.register(listener, selectors.EVENT_READ, "accept")
        selector.register(wake, selectors.EVENT_READ, "wake")
        try:
            while not self._stopping.is_set():
                for key, events in selector.select(self._timeout()):
                    if key.data == "accept":
                        self._accept(selector, listener)
                    elif key.data == "wake":
                        wake.recv(4096)
                    else:
                        if events & selectors.EVENT_WRITE:
                            key.data.blocked = False
                        if events & selectors.EVENT_READ:
                            self._read(selector, key.data)
                if self._drop_all.is_set():
                    self._drop_all.clear()
                    for client in self._snapshot():
                        self._close(selector, client)
                self._flush(selector)
        except Exception:  # a bug must not leave sockets open; log it and shut down
            _log.exception("GCS simulator loop failed")
        finally:
            for client in self._snapshot():
                self._close(selector, client)
            selector.close()
            listener.close()
            self._listener = None

    def _snapshot(self) -> list[_Client]:
        with self._clients_lock:
            return list(self._clients.values())

    def _timeout(self) -> float:
        now = time.monotonic()
        due = [c.outbox[0][0] for c in self._snapshot() if c.outbox and not c.blocked]
        return max(0.0, min([_IDLE_S, *(d - now for d in due)]))

    def _accept(self, selector: selectors.BaseSelector, listener: socket.socket) -> None:
        try:
            sock, _ = listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock)
        with self._clients_lock:
            self._clients[sock.fileno()] = client
            self.connections += 1
        selector.register(sock, selectors.EVENT_READ, client)
        self._admit(selector, client)

    def _admit(self, selector: selectors.BaseSelector, newcomer: _Client) -> None:
        """Keep ``newcomer`` within the cap, making room from a quiet client, or close it (module notes)."""
        others = [c for c in self._snapshot() if c is not newcomer]
        if len(others) < self._max_clients:
            return
        now = time.monotonic()
        quiet = [c for c in others if now - c.last_heard >= self._quiet_s]
        if quiet:
            oldest = min(quiet, key=lambda c: c.last_heard)
            _log.warning("GCS simulator: %d clients; one quiet for %.0f s closed for a new one", len(others),
                         now - oldest.last_heard)
            self._close(selector, oldest)
            return
        _log.warning("GCS simulator: %d clients, none quiet: a new connection refused", len(others))
        self.refused += 1
        self._close(selector, newcomer)

    def _read(self, selector: selectors.BaseSelector, client: _Client) -> None:
        try:
            data = client.sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._close(selector, client)
            return
        now = client.last_heard = time.monotonic()
        for event in client.assembler.feed(data):
            delivery = self.controller.handle(event)
            due = max(now, client.last_due)
            for delay_s, chunk in delivery.pieces:
                due += delay_s
                client.outbox.append((due, chunk))
                client.pending += len(chunk)
            client.last_due = due
            if client.pending > MAX_PENDING_BYTES:
                _log.warning("GCS simulator: a client left %d reply bytes unread; disconnected", client.pending)
                self._close(selector, client)
                return
            if delivery.close:
                client.close_when_sent = True
                break  # the connection is gone: nothing after this command is read

    def _flush(self, selector: selectors.BaseSelector) -> None:
        now = time.monotonic()
        for client in self._snapshot():
            try:
                while not client.blocked and client.outbox and client.outbox[0][0] <= now:
                    due, chunk = client.outbox[0]
                    sent = client.sock.send(chunk)
                    client.pending -= sent
                    if sent < len(chunk):  # the peer's buffer is full: the rest when it is writable
                        client.outbox[0] = (due, chunk[sent:])
                        client.blocked = True
                    else:
                        client.outbox.popleft()
            except BlockingIOError:
                client.blocked = True
            except OSError:
                self._close(selector, client)
                continue
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if client.blocked else 0)
            if selector.get_key(client.sock).events != events:
                selector.modify(client.sock, events, client)
            if client.close_when_sent and not client.outbox:
                self._close(selector, client)

    def _close(self, selector: selectors.BaseSelector, client: _Client) -> None:
        with self._clients_lock:
            if self._clients.get(client.sock.fileno()) is not client:
                return
            del self._clients[client.sock.fileno()]
        try:
            selector.unregister(client.sock)
        except (KeyError, ValueError):
            pass
        client.sock.close()


def _family(host: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ":" in host else socket.AF_INET
