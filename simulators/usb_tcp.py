"""A USB bus served over TCP: any pyusb backend's devices reached from another process (``usbtcp://``).

The device side of :mod:`wavestack.drivers.u3v.usb_tcp` (written again here from the wire format,
as every simulator re-implements its protocol): each request names a pyusb backend call, which
this server makes on the backend it wraps (the simulated camera's
:class:`~wavestack.simulators.u3v.SimulatedUsbBackend`) and answers. Wire format, both ways: a
4-byte big-endian length of a UTF-8 JSON header, a 4-byte length of a binary payload, the header,
the payload. Requests ``{"op": NAME, "args": {...}}``; replies ``{"value": ...}``,
``{"usb_error": [message, backend_code, errno]}`` or ``{"index_error": message}``. Devices and
handles cross the wire as integer references. One thread per connection (a client opens one per
thread of its own), one thread accepting; :meth:`UsbTcpServer.stop` closes every socket and joins
every thread. :meth:`UsbTcpServer.disconnect_clients` drops the connections (a fault switch: to the
host it is a camera gone from the bus until it enumerates again).
"""

from __future__ import annotations

import array
import errno
import json
import logging
import socket
import struct
import threading
from typing import Any

import usb.core

__all__ = ["UsbTcpServer"]

_log = logging.getLogger(__name__)
_HEAD = struct.Struct(">II")
_MAX_HEADER = 1 << 20
_MAX_PAYLOAD = 64 << 20

_DEVICE_FIELDS = ("bLength", "bDescriptorType", "bcdUSB", "bDeviceClass", "bDeviceSubClass", "bDeviceProtocol",
                  "bMaxPacketSize0", "idVendor", "idProduct", "bcdDevice", "iManufacturer", "iProduct",
                  "iSerialNumber", "bNumConfigurations", "bus", "address", "port_number", "port_numbers", "speed")
_CONFIG_FIELDS = ("bLength", "bDescriptorType", "wTotalLength", "bNumInterfaces", "bConfigurationValue",
                  "iConfiguration", "bmAttributes", "bMaxPower", "extra_descriptors")
_INTERFACE_FIELDS = ("bLength", "bDescriptorType", "bInterfaceNumber", "bAlternateSetting", "bNumEndpoints",
                     "bInterfaceClass", "bInterfaceSubClass", "bInterfaceProtocol", "iInterface", "extra_descriptors")
_ENDPOINT_FIELDS = ("bLength", "bDescriptorType", "bEndpointAddress", "bmAttributes", "wMaxPacketSize", "bInterval",
                    "bRefresh", "bSynchAddress", "extra_descriptors")


def _fields(descriptor: Any, names: tuple[str, ...]) -> dict[str, Any]:
    out = {}
    for name in names:
        value = getattr(descriptor, name, None)
        out[name] = list(value) if isinstance(value, (tuple, list, bytes, array.array)) else value
    return out


def _read_exactly(sock: socket.socket, count: int) -> bytes | None:
    chunks, left = [], count
    while left:
        chunk = sock.recv(min(left, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


class UsbTcpServer:
    """Serve a pyusb backend's bus on TCP (module notes); a context manager.

    Parameters
    ----------
    backend : usb.backend.IBackend
        The bus served (the simulated camera's backend).
    host, port : str, int
        Where to listen (port 0: a free one, read :attr:`port` after :meth:`start`).
    """

    def __init__(self, backend: Any, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self._backend = backend
        self._host, self._port = host, int(port)
        self._listener: socket.socket | None = None
        self._lock = threading.Lock()
        self._clients: dict[socket.socket, threading.Thread] = {}
        self._devices: dict[int, Any] = {}
        self._device_refs: dict[int, int] = {}  # id(device) -> ref
        self._handles: dict[int, Any] = {}
        self._next = 1
        self._accepting: threading.Thread | None = None

    @property
    def port(self) -> int:
        return self._port

    def start(self) -> UsbTcpServer:
        listener = socket.create_server((self._host, self._port), backlog=16)
        self._listener, self._port = listener, listener.getsockname()[1]
        self._accepting = threading.Thread(target=self._accept, name=f"usb-tcp-{self._port}", daemon=True)
        self._accepting.start()
        return self

    def stop(self) -> None:
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
        """Drop every connection and wait for their threads (the handles they opened are closed)."""
        with self._lock:
            clients = list(self._clients.items())
        for sock, _ in clients:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for _, thread in clients:
            thread.join(5.0)
        with self._lock:
            handles, self._handles = list(self._handles.values()), {}
        for handle in handles:
            try:
                self._backend.close_device(handle)
            except usb.core.USBError:
                pass

    # --- serving ------------------------------------------------------------------------------
    def _accept(self) -> None:
        assert self._listener is not None
        while True:
            try:
                sock, _ = self._listener.accept()
            except OSError:
                return
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            thread = threading.Thread(target=self._serve, args=(sock,), name=f"usb-tcp-client-{self._port}",
                                      daemon=True)
            with self._lock:
                self._clients[sock] = thread
            thread.start()

    def _serve(self, sock: socket.socket) -> None:
        try:
            while True:
                head = _read_exactly(sock, _HEAD.size)
                if head is None:
                    return
                size, data_size = _HEAD.unpack(head)
                if size > _MAX_HEADER or data_size > _MAX_PAYLOAD:
                    _log.warning("usb-tcp: request of %d + %d bytes refused; connection closed", size, data_size)
                    return
                header, payload = _read_exactly(sock, size), _read_exactly(sock, data_size)
                if header is None or payload is None:
                    return
                reply, data = self._answer(json.loads(header), payload)
                body = json.dumps(reply).encode()
                sock.sendall(_HEAD.pack(len(body), len(data)) + body + data)
        except (OSError, ValueError) as error:
            _log.info("usb-tcp: connection ended: %s", error)
        finally:
            with self._lock:
                self._clients.pop(sock, None)
            sock.close()

    def _answer(self, request: dict[str, Any], payload: bytes) -> tuple[dict[str, Any], bytes]:
        try:
            value, data = self._call(str(request.get("op")), dict(request.get("args") or {}), payload)
        except usb.core.USBError as error:
            return {"usb_error": [error.strerror or str(error), error.backend_error_code, error.errno]}, b""
        except (IndexError, KeyError) as error:
            return {"index_error": str(error)}, b""
        return {"value": value}, data

    def _ref(self, table: dict[int, Any], item: Any) -> int:
        with self._lock:
            ref, self._next = self._next, self._next + 1
            table[ref] = item
        return ref

    def _call(self, op: str, a: dict[str, Any], payload: bytes) -> tuple[Any, bytes]:  # noqa: C901 - one dispatch
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
            return _fields(b.get_configuration_descriptor(self._devices[a["dev"]], a["config"]), _CONFIG_FIELDS), b""
        if op == "get_interface_descriptor":
            d = b.get_interface_descriptor(self._devices[a["dev"]], a["intf"], a["alt"], a["config"])
            return _fields(d, _INTERFACE_FIELDS), b""
        if op == "get_endpoint_descriptor":
            d = b.get_endpoint_descriptor(self._devices[a["dev"]], a["ep"], a["intf"], a["alt"], a["config"])
            return _fields(d, _ENDPOINT_FIELDS), b""
        if op == "open_device":
            return self._ref(self._handles, b.open_device(self._devices[a["dev"]])), b""
        if op == "close_device":
            with self._lock:
                handle = self._handles.pop(a["handle"], None)
            if handle is not None:
                b.close_device(handle)
            return None, b""
        handle = self._handles.get(a.pop("handle"))
        if handle is None:  # dropped with its connection (disconnect_clients): the device is gone for it
            raise usb.core.USBError("No such device (it may have been disconnected): handle closed", -4, errno.ENODEV)
        if op == "bulk_write":
            return b.bulk_write(handle, a["ep"], a["intf"], array.array("B", payload), a["timeout"]), b""
        if op == "bulk_read":
            buff = array.array("B", bytes(a["size"]))
            count = b.bulk_read(handle, a["ep"], a["intf"], buff, a["timeout"])
            return count, buff.tobytes()[:count]
        if op == "ctrl_transfer":
            inbound = bool(a["bmRequestType"] & 0x80)
            data = array.array("B", bytes(a["size"]) if inbound else payload)
            count = b.ctrl_transfer(handle, a["bmRequestType"], a["bRequest"], a["wValue"], a["wIndex"], data,
                                    a["timeout"])
            return count, data.tobytes()[:count] if inbound else b""
        simple = {"set_configuration", "get_configuration", "set_interface_altsetting", "claim_interface",
                  "release_interface", "clear_halt", "reset_device", "is_kernel_driver_active",
                  "detach_kernel_driver", "attach_kernel_driver"}
        if op not in simple:
            raise KeyError(f"unknown operation {op!r}")
        return getattr(b, op)(handle, *a.values()), b""
