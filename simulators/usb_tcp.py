"""A USB bus served over TCP: any pyusb backend's devices reached from another process (``usbtcp://``).

The device side of :mod:`wavestack.drivers.usb_tcp` (written again here from the wire format,
as every simulator re-implements its protocol): each request names a pyusb backend call, which
this server makes on the backend it wraps (the simulated camera's
:class:`~wavestack.simulators.u3v.SimulatedUsbBackend`) and answers. Wire format, both ways: a
4-byte big-endian length of a UTF-8 JSON header, a 4-byte length of a binary payload, the header,
the payload. Requests ``{"op": NAME, "args": {...}}``; replies ``{"value": ...}``,
``{"usb_error": [message, backend_code, errno]}`` or ``{"index_error": message}``.

Who may do what (a server on a network trusts no connection it did not give a role to):

- **Sessions.** A connection's first request is ``hello`` with the session it joins (None: a new
  one); the answer is the session's id, a random token (a new session when the one named is
  gone). Device handles belong to the session that opened them: another session's request naming
  one is answered ``ENODEV``, as for a closed handle. A session ends when its last connection
  closes; its handles are closed then.
- **Ownership.** The first session that claims an interface of a device owns the device until it
  ends: any other session may enumerate it and read its descriptors, nothing else (``EBUSY``).
- **Bounds.** A header holds at most ``max_header_bytes``; a payload, and the size a read may ask
  for, at most ``max_payload_bytes``; a request over them is answered (``EOVERFLOW``) and its
  connection closed. A request must arrive whole within ``request_timeout_s`` of its first byte; a
  connection that holds no handle and sends nothing for ``idle_timeout_s`` is closed. At most
  ``max_connections`` connections are served; one more is closed at once.
- **Every failure answered.** A request that fails for any reason (unknown operation, bad
  arguments, a backend error) gets a ``usb_error`` reply and the connection goes on; nothing a
  peer sends escapes a connection's thread.

One thread per connection, one thread accepting; :meth:`UsbTcpServer.stop` closes every socket
and joins every thread. :meth:`UsbTcpServer.disconnect_clients` drops the connections (a fault
switch: to the host it is a camera gone from the bus until it enumerates again).
"""

from __future__ import annotations

import array
import errno
import json
import logging
import secrets
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import usb.core

__all__ = ["UsbTcpServer"]

_log = logging.getLogger(__name__)
_HEAD = struct.Struct(">II")
_POLL_S = 0.25  # how often a waiting connection looks at its timeouts and the stop flag
_MAX_TIMEOUT_MS = 60_000  # the longest transfer timeout a request may ask for

_DEVICE_FIELDS = ("bLength", "bDescriptorType", "bcdUSB", "bDeviceClass", "bDeviceSubClass", "bDeviceProtocol",
                  "bMaxPacketSize0", "idVendor", "idProduct", "bcdDevice", "iManufacturer", "iProduct",
                  "iSerialNumber", "bNumConfigurations", "bus", "address", "port_number", "port_numbers", "speed")
_CONFIG_FIELDS = ("bLength", "bDescriptorType", "wTotalLength", "bNumInterfaces", "bConfigurationValue",
                  "iConfiguration", "bmAttributes", "bMaxPower", "extra_descriptors")
_INTERFACE_FIELDS = ("bLength", "bDescriptorType", "bInterfaceNumber", "bAlternateSetting", "bNumEndpoints",
                     "bInterfaceClass", "bInterfaceSubClass", "bInterfaceProtocol", "iInterface", "extra_descriptors")
_ENDPOINT_FIELDS = ("bLength", "bDescriptorType", "bEndpointAddress", "bmAttributes", "wMaxPacketSize", "bInterval",
                    "bRefresh", "bSynchAddress", "extra_descriptors")
_HANDLE_OPS = frozenset({"close_device", "set_configuration", "get_configuration", "set_interface_altsetting",
                         "claim_interface", "release_interface", "bulk_write", "bulk_read", "ctrl_transfer",
                         "clear_halt", "reset_device", "is_kernel_driver_active", "detach_kernel_driver",
                         "attach_kernel_driver"})
_READ_ONLY_OPS = frozenset({"close_device", "get_configuration", "is_kernel_driver_active"})


class _Refused(Exception):
    """A request answered with a usb_error (errno and message)."""

    def __init__(self, number: int, message: str) -> None:
        super().__init__(message)
        self.number = number


class _Gone(Exception):
    """The connection ended (closed, timed out, over a bound, or the server stops)."""


def _fields(descriptor: Any, names: tuple[str, ...]) -> dict[str, Any]:
    out = {}
    for name in names:
        value = getattr(descriptor, name, None)
        out[name] = list(value) if isinstance(value, (tuple, list, bytes, array.array)) else value
    return out


def _integer(args: dict[str, Any], name: str, low: int = 0, high: int = 0xFFFFFFFF) -> int:
    value = args.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise _Refused(errno.EINVAL, f"argument {name!r} must be an integer {low}..{high}, got {value!r:.40}")
    return value


@dataclass(eq=False)
class _Session:
    token: str
    connections: int = 0
    handles: dict[int, tuple[Any, int]] = field(default_factory=dict)  # ref -> (backend handle, device ref)


class UsbTcpServer:
    """Serve a pyusb backend's bus on TCP (module notes); a context manager.

    Parameters
    ----------
    backend : usb.backend.IBackend
        The bus served (the simulated camera's backend).
    host, port : str, int
        Where to listen (port 0: a free one, read :attr:`port` after :meth:`start`).
    max_connections : int
        Connections served at once.
    max_header_bytes, max_payload_bytes : int
        Bounds of a request's header and payload (and of the size a read may ask for).
    request_timeout_s, idle_timeout_s : float
        How long a started request may take to arrive; how long a connection holding no handle may
        stay silent.
    """

    def __init__(self, backend: Any, *, host: str = "127.0.0.1", port: int = 0, max_connections: int = 8,
                 max_header_bytes: int = 1 << 16, max_payload_bytes: int = 32 << 20,
                 request_timeout_s: float = 5.0, idle_timeout_s: float = 30.0) -> None:
        self._backend = backend
        self._host, self._port = host, int(port)
        self.max_connections = max_connections
        self._max_header, self._max_payload = max_header_bytes, max_payload_bytes
        self._request_timeout_s, self._idle_timeout_s = request_timeout_s, idle_timeout_s
        self._listener: socket.socket | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._clients: dict[socket.socket, threading.Thread] = {}
        self._sessions: dict[str, _Session] = {}
        self._owners: dict[int, _Session] = {}  # device ref -> the session that claimed it
        self._devices: dict[int, Any] = {}
        self._device_refs: dict[int, int] = {}  # id(device) -> ref
        self._next = 1
        self._accepting: threading.Thread | None = None
        self.refused_connections = 0  #: connections closed at once: over ``max_connections``

    @property
    def port(self) -> int:
        return self._port

    @property
    def connection_count(self) -> int:
        """Connections served now."""
        with self._lock:
            return len(self._clients)

    def start(self) -> UsbTcpServer:
        listener = socket.create_server((self._host, self._port), backlog=16)
        self._listener, self._port = listener, listener.getsockname()[1]
        self._stop.clear()
        self._accepting = threading.Thread(target=self._accept, name=f"usb-tcp-{self._port}", daemon=True)
        self._accepting.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._listener is not None:
            try:
                self._listener.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._listener.close()
        if self._accepting is not None:
            self._accepting.join(5.0)
        self.disconnect_clients()

    def __enter__(self) -> UsbTcpServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def disconnect_clients(self) -> None:
        """End every session (its handles closed), drop every connection and wait for their threads."""
        with self._lock:
            clients = list(self._clients.items())
            sessions, self._sessions, self._owners = list(self._sessions.values()), {}, {}
            handles = [handle for session in sessions for handle, _ in session.handles.values()]
            for session in sessions:
                session.handles = {}
        for handle in handles:
            try:
                self._backend.close_device(handle)
            except usb.core.USBError:
                pass
        for sock, _ in clients:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for _, thread in clients:
            thread.join(5.0)

    # --- serving ------------------------------------------------------------------------------
    def _accept(self) -> None:
        assert self._listener is not None
        while True:
            try:
                sock, peer = self._listener.accept()
            except OSError:
                return
            with self._lock:
                full = len(self._clients) >= self.max_connections
                if full:
                    self.refused_connections += 1
            if full:
                _log.warning("usb-tcp: connection from %s refused: %d connections served already", peer,
                             self.max_connections)
                sock.close()
                continue
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            thread = threading.Thread(target=self._serve, args=(sock,), name=f"usb-tcp-client-{self._port}",
                                      daemon=True)
            with self._lock:
                self._clients[sock] = thread
            thread.start()

    def _serve(self, sock: socket.socket) -> None:
        session: _Session | None = None
        try:
            while True:
                header, payload = self._receive(sock, session)
                reply, data, session = self._answer(header, payload, session)
                body = json.dumps(reply).encode()
                sock.settimeout(self._request_timeout_s)
                sock.sendall(_HEAD.pack(len(body), len(data)) + body + data)
        except (_Gone, OSError) as error:
            _log.info("usb-tcp: connection ended: %s", error)
        finally:
            with self._lock:
                self._clients.pop(sock, None)
            sock.close()
            if session is not None:
                self._leave(session)

    def _receive(self, sock: socket.socket, session: _Session | None) -> tuple[bytes, bytes]:
        """One request's header and payload; _Gone when the connection ends or breaks a bound."""
        head = self._read(sock, _HEAD.size, session, first=True)
        size, data_size = _HEAD.unpack(head)
        if size > self._max_header or data_size > self._max_payload:
            self._refuse_and_close(sock, f"a request of {size} + {data_size} bytes; at most {self._max_header} + "
                                   f"{self._max_payload}")
        return self._read(sock, size, session), self._read(sock, data_size, session)

    def _read(self, sock: socket.socket, count: int, session: _Session | None, *, first: bool = False) -> bytes:
        """Exactly ``count`` bytes, within the request timeout (the idle timeout before a request's first byte)."""
        chunks, left, started = [], count, time.monotonic()
        sock.settimeout(_POLL_S)
        while left:
            try:
                chunk = sock.recv(min(left, 1 << 20))
            except TimeoutError:
                waited = time.monotonic() - started
                if self._stop.is_set():
                    raise _Gone("the server stops") from None
                if first and left == count:  # between requests: idle
                    if waited > self._idle_timeout_s and not self._holds_handles(session):
                        raise _Gone(f"idle for {waited:.0f} s without a handle") from None
                elif waited > self._request_timeout_s:
                    raise _Gone(f"a request not complete after {waited:.1f} s") from None
                continue
            if not chunk:
                raise _Gone("closed by the peer")
            if first and left == count:
                started = time.monotonic()  # the request starts with its first byte
            chunks.append(chunk)
            left -= len(chunk)
        return b"".join(chunks)

    def _refuse_and_close(self, sock: socket.socket, why: str) -> None:
        _log.warning("usb-tcp: %s; connection closed", why)
        body = json.dumps({"usb_error": [f"Value too large: {why}", -1, errno.EOVERFLOW]}).encode()
        try:
            sock.settimeout(1.0)
            sock.sendall(_HEAD.pack(len(body), 0) + body)
        except OSError:
            pass
        raise _Gone(why)

    def _holds_handles(self, session: _Session | None) -> bool:
        with self._lock:
            return session is not None and bool(session.handles)

    # --- sessions -----------------------------------------------------------------------------
    def _hello(self, args: dict[str, Any], session: _Session | None) -> _Session:
        if session is not None:
            raise _Refused(errno.EINVAL, "hello: this connection has a session already")
        wanted = args.get("session")
        with self._lock:
            joined = self._sessions.get(wanted) if isinstance(wanted, str) else None
            if joined is None:
                joined = _Session(secrets.token_hex(16))
                self._sessions[joined.token] = joined
            joined.connections += 1
        return joined

    def _leave(self, session: _Session) -> None:
        with self._lock:
            session.connections -= 1
            if session.connections > 0:
                return
            self._sessions.pop(session.token, None)
            handles, session.handles = list(session.handles.values()), {}
            for device_ref in [ref for ref, owner in self._owners.items() if owner is session]:
                del self._owners[device_ref]
        for handle, _ in handles:
            try:
                self._backend.close_device(handle)
            except usb.core.USBError:
                pass

    # --- requests -----------------------------------------------------------------------------
    def _answer(self, header: bytes, payload: bytes,
                session: _Session | None) -> tuple[dict[str, Any], bytes, _Session | None]:
        """The reply to one request; every failure is a reply (module notes)."""
        try:
            request = json.loads(header.decode("utf-8"))
            if not isinstance(request, dict) or not isinstance(request.get("args", {}), dict):
                raise _Refused(errno.EINVAL, "a request must be {\"op\": NAME, \"args\": {...}}")
            op, args = str(request.get("op")), dict(request.get("args") or {})
            if op == "hello":
                session = self._hello(args, session)
                return {"value": session.token}, b"", session
            if session is None:
                raise _Refused(errno.EACCES, "say hello first: a connection joins a session before any request")
            value, data = self._call(op, args, payload, session)
        except usb.core.USBError as error:
            return {"usb_error": [error.strerror or str(error), error.backend_error_code or -99, error.errno]}, b"", \
                session
        except IndexError as error:
            return {"index_error": str(error)}, b"", session
        except _Refused as refusal:
            return {"usb_error": [str(refusal), -99, refusal.number]}, b"", session
        except Exception as error:  # noqa: BLE001 - a peer's request never ends the connection's thread
            _log.info("usb-tcp: request failed: %s: %s", type(error).__name__, error)
            return {"usb_error": [f"Invalid request: {type(error).__name__}: {error}", -2, errno.EINVAL]}, b"", \
                session
        return {"value": value}, data, session

    def _ref(self, table: dict[int, Any], item: Any) -> int:
        with self._lock:
            ref, self._next = self._next, self._next + 1
            table[ref] = item
        return ref

    def _device(self, args: dict[str, Any]) -> Any:
        device = self._devices.get(_integer(args, "dev"))
        if device is None:
            raise _Refused(errno.ENODEV, "No such device (it may have been disconnected)")
        return device

    def _call(self, op: str, a: dict[str, Any], payload: bytes, session: _Session) -> tuple[Any, bytes]:
        b = self._backend
        if op == "enumerate_devices":
            found = []
            for dev in b.enumerate_devices():
                ref = self._device_refs.get(id(dev))
                if ref is None or self._devices.get(ref) is not dev:
                    ref = self._ref(self._devices, dev)
                    self._device_refs[id(dev)] = ref
                found.append([ref, _fields(b.get_device_descriptor(dev), _DEVICE_FIELDS)])
            return found, b""
        if op == "get_configuration_descriptor":
            return _fields(b.get_configuration_descriptor(self._device(a), _integer(a, "config")), _CONFIG_FIELDS), b""
        if op == "get_interface_descriptor":
            d = b.get_interface_descriptor(self._device(a), _integer(a, "intf"), _integer(a, "alt"),
                                           _integer(a, "config"))
            return _fields(d, _INTERFACE_FIELDS), b""
        if op == "get_endpoint_descriptor":
            d = b.get_endpoint_descriptor(self._device(a), _integer(a, "ep"), _integer(a, "intf"), _integer(a, "alt"),
                                          _integer(a, "config"))
            return _fields(d, _ENDPOINT_FIELDS), b""
        if op == "open_device":
            device_ref = _integer(a, "dev")
            handle = b.open_device(self._device(a))
            return self._ref_handle(session, handle, device_ref), b""
        if op not in _HANDLE_OPS:
            raise _Refused(errno.ENOSYS, f"unknown operation {op!r}")
        return self._handle_call(op, a, payload, session)

    def _ref_handle(self, session: _Session, handle: Any, device_ref: int) -> int:
        with self._lock:
            ref, self._next = self._next, self._next + 1
            session.handles[ref] = (handle, device_ref)
        return ref

    def _handle_call(self, op: str, a: dict[str, Any], payload: bytes, session: _Session) -> tuple[Any, bytes]:
        b = self._backend
        ref = _integer(a, "handle")
        with self._lock:
            entry = session.handles.get(ref)
            if entry is not None and op == "close_device":
                del session.handles[ref]
            owner = self._owners.get(entry[1]) if entry is not None else None
            if entry is not None and op == "claim_interface" and owner is None:
                self._owners[entry[1]] = owner = session
        if entry is None:  # another session's, or dropped with its connection: gone for this one
            raise _Refused(errno.ENODEV, "No such device (it may have been disconnected): handle closed")
        handle, _ = entry
        if op == "close_device":
            b.close_device(handle)
            return None, b""
        if owner is not None and owner is not session and op not in _READ_ONLY_OPS:
            raise _Refused(errno.EBUSY, "Resource busy: another session has claimed this device")
        if op == "bulk_write":
            return b.bulk_write(handle, _integer(a, "ep"), _integer(a, "intf"), array.array("B", payload),
                                _integer(a, "timeout", 0, _MAX_TIMEOUT_MS)), b""
        if op == "bulk_read":
            buff = array.array("B", bytes(_integer(a, "size", 0, self._max_payload)))
            count = b.bulk_read(handle, _integer(a, "ep"), _integer(a, "intf"), buff,
                                _integer(a, "timeout", 0, _MAX_TIMEOUT_MS))
            return count, buff.tobytes()[:count]
        if op == "ctrl_transfer":
            inbound = bool(_integer(a, "bmRequestType", 0, 255) & 0x80)
            data = array.array("B", bytes(_integer(a, "size", 0, self._max_payload)) if inbound else payload)
            count = b.ctrl_transfer(handle, a["bmRequestType"], _integer(a, "bRequest", 0, 255),
                                    _integer(a, "wValue", 0, 0xFFFF), _integer(a, "wIndex", 0, 0xFFFF), data,
                                    _integer(a, "timeout", 0, _MAX_TIMEOUT_MS))
            return count, data.tobytes()[:count] if inbound else b""
        arguments = {"set_configuration": ("config_value",), "set_interface_altsetting": ("intf", "altsetting"),
                     "claim_interface": ("intf",), "release_interface": ("intf",), "clear_halt": ("ep",),
                     "is_kernel_driver_active": ("intf",), "detach_kernel_driver": ("intf",),
                     "attach_kernel_driver": ("intf",)}.get(op, ())
        return getattr(b, op)(handle, *(_integer(a, name) for name in arguments)), b""
