"""A pyusb backend whose USB transfers travel over TCP to a USB bus on another host (``usbtcp://``).

A USB3 Vision camera is a USB device of the host it is plugged into; this backend lets the
unchanged driver (:class:`~wavestack.drivers.u3v.U3VCamera`) reach a camera served by another
process, in the manner of USB/IP but in user space: every pyusb backend call (enumeration,
descriptors, open, claim, bulk and control transfers, halts, reset) is one request and one reply
on a TCP connection. It exists for the remote alignment-bench simulator (``wavestack sim
align-bench``), which serves its simulated camera this way; a camera on a local bus needs none.

Wire format, both ways: a 4-byte big-endian length of a UTF-8 JSON header, a 4-byte length of a
binary payload, the header, the payload. A request header is ``{"op": NAME, "args": {...}}``
(devices and handles as integer references the server hands out); a reply is ``{"value": ...}``,
``{"usb_error": [message, backend_code, errno]}`` (re-raised as pyusb raises it) or
``{"index_error": message}``. Each thread gets its own connection (the stream thread's long bulk
reads never hold up the control channel); a connection that fails reads as an unplugged device
(``ENODEV``), and enumeration on an unreachable server finds no device.
"""

from __future__ import annotations

import array
import errno
import json
import socket
import struct
import threading
import urllib.parse
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core

__all__ = ["UsbTcpBackend", "parse_usbtcp_url"]

_HEAD = struct.Struct(">II")
_MAX_HEADER = 1 << 20
_MAX_PAYLOAD = 64 << 20
_CONNECT_S = 2.0
_MARGIN_S = 5.0


def parse_usbtcp_url(url: str) -> tuple[str, int, str | None]:
    """``usbtcp://HOST:PORT[/SERIAL]`` -> (host, port, serial or None).

    Example
    -------
    >>> parse_usbtcp_url("usbtcp://127.0.0.1:5100/WS-SIM-0001")
    ('127.0.0.1', 5100, 'WS-SIM-0001')

    Raises
    ------
    ValueError
        Another scheme, or no host or port.
    """
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "usbtcp" or not parts.hostname or parts.port is None:
        raise ValueError(f"url: expected usbtcp://HOST:PORT[/SERIAL], got {url!r}")
    return parts.hostname, parts.port, parts.path.strip("/") or None


class _Link:
    """One TCP connection and its framing."""

    def __init__(self, host: str, port: int) -> None:
        self.sock = socket.create_connection((host, port), timeout=_CONNECT_S)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def call(self, header: dict[str, Any], payload: bytes, timeout_s: float | None) -> tuple[dict[str, Any], bytes]:
        body = json.dumps(header).encode()
        self.sock.settimeout(timeout_s)
        self.sock.sendall(_HEAD.pack(len(body), len(payload)) + body + payload)
        size, data_size = _HEAD.unpack(self._exactly(_HEAD.size))
        if size > _MAX_HEADER or data_size > _MAX_PAYLOAD:
            raise ConnectionError(f"reply of {size} + {data_size} bytes exceeds the limits")
        reply = json.loads(self._exactly(size))
        return reply, self._exactly(data_size)

    def _exactly(self, count: int) -> bytes:
        chunks, left = [], count
        while left:
            chunk = self.sock.recv(min(left, 1 << 20))
            if not chunk:
                raise ConnectionError("the USB server closed the connection")
            chunks.append(chunk)
            left -= len(chunk)
        return b"".join(chunks)

    def close(self) -> None:
        self.sock.close()


class _Device:
    """A remote device as ``enumerate_devices`` yields it."""

    def __init__(self, ref: int, descriptor: dict[str, Any]) -> None:
        self.ref = ref
        self.descriptor = _namespace(descriptor)


def _namespace(fields: dict[str, Any]) -> SimpleNamespace:
    return SimpleNamespace(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


class UsbTcpBackend(usb.backend.IBackend):
    """pyusb backend forwarding every call to a USB server over TCP (module notes).

    Parameters
    ----------
    host, port : str, int
        The server (``wavestack sim align-bench`` prints ``usb HOST:PORT``).

    Example
    -------
    >>> backend = UsbTcpBackend("127.0.0.1", 1)  # nothing listens on port 1: no device on that bus
    >>> list(backend.enumerate_devices())
    []
    """

    def __init__(self, host: str, port: int) -> None:
        self._address = (host, int(port))
        self._local = threading.local()
        self._lock = threading.Lock()
        self._links: list[_Link] = []
        self._open_handles = 0

    # --- the connection -----------------------------------------------------------------------
    def _link(self) -> _Link:
        link = getattr(self._local, "link", None)
        if link is None:
            link = _Link(*self._address)
            self._local.link = link
            with self._lock:
                self._links.append(link)
        return link

    def _drop_link(self) -> None:
        link = getattr(self._local, "link", None)
        self._local.link = None
        if link is not None:
            link.close()
            with self._lock:
                if link in self._links:
                    self._links.remove(link)

    def close(self) -> None:
        """Close every connection (a later call opens new ones)."""
        with self._lock:
            links, self._links = self._links, []
        for link in links:
            link.close()
        self._local = threading.local()

    def _call(self, op: str, payload: bytes = b"", timeout_ms: int | None = None, **args: Any) -> tuple[Any, bytes]:
        timeout = None if not timeout_ms else timeout_ms / 1000.0 + _MARGIN_S
        for attempt in range(2):  # a kept connection the server dropped since is retried once on a new one
            reused = getattr(self._local, "link", None) is not None
            try:
                reply, data = self._link().call({"op": op, "args": args}, payload, timeout)
                break
            except (OSError, ValueError) as error:  # refused, reset, closed, timed out, garbled
                self._drop_link()
                if reused and attempt == 0 and not isinstance(error, TimeoutError):
                    continue
                raise usb.core.USBError(f"No such device (it may have been disconnected): USB server "
                                        f"{self._address[0]}:{self._address[1]}: {error}", -4, errno.ENODEV) from None
        if "usb_error" in reply:
            message, code, number = reply["usb_error"]
            cls = usb.core.USBTimeoutError if number == errno.ETIMEDOUT else usb.core.USBError
            raise cls(message, code, number)
        if "index_error" in reply:
            raise IndexError(reply["index_error"])
        return reply.get("value"), data

    # --- enumeration and descriptors ----------------------------------------------------------
    def enumerate_devices(self) -> Iterator[_Device]:
        try:
            found, _ = self._call("enumerate_devices")
        except usb.core.USBError:
            return iter(())
        return iter([_Device(ref, descriptor) for ref, descriptor in found])

    def get_parent(self, dev: _Device) -> None:
        return None

    def get_device_descriptor(self, dev: _Device) -> Any:
        return dev.descriptor

    def get_configuration_descriptor(self, dev: _Device, config: int) -> Any:
        return _namespace(self._call("get_configuration_descriptor", dev=dev.ref, config=config)[0])

    def get_interface_descriptor(self, dev: _Device, intf: int, alt: int, config: int) -> Any:
        return _namespace(self._call("get_interface_descriptor", dev=dev.ref, intf=intf, alt=alt, config=config)[0])

    def get_endpoint_descriptor(self, dev: _Device, ep: int, intf: int, alt: int, config: int) -> Any:
        return _namespace(self._call("get_endpoint_descriptor", dev=dev.ref, ep=ep, intf=intf, alt=alt,
                                     config=config)[0])

    # --- handles ------------------------------------------------------------------------------
    def open_device(self, dev: _Device) -> int:
        handle = int(self._call("open_device", dev=dev.ref)[0])
        with self._lock:
            self._open_handles += 1
        return handle

    def close_device(self, dev_handle: int) -> None:
        try:
            self._call("close_device", handle=dev_handle)
        except usb.core.USBError:
            pass  # the server is gone: nothing left to close there
        with self._lock:
            self._open_handles = max(0, self._open_handles - 1)
            last = self._open_handles == 0
        if last:
            self.close()

    def set_configuration(self, dev_handle: int, config_value: int) -> None:
        self._call("set_configuration", handle=dev_handle, config_value=config_value)

    def get_configuration(self, dev_handle: int) -> int:
        return int(self._call("get_configuration", handle=dev_handle)[0])

    def set_interface_altsetting(self, dev_handle: int, intf: int, altsetting: int) -> None:
        self._call("set_interface_altsetting", handle=dev_handle, intf=intf, altsetting=altsetting)

    def claim_interface(self, dev_handle: int, intf: int) -> None:
        self._call("claim_interface", handle=dev_handle, intf=intf)

    def release_interface(self, dev_handle: int, intf: int) -> None:
        self._call("release_interface", handle=dev_handle, intf=intf)

    # --- transfers ----------------------------------------------------------------------------
    def bulk_write(self, dev_handle: int, ep: int, intf: int, data: array.array[int], timeout: int) -> int:
        return int(self._call("bulk_write", data.tobytes(), timeout, handle=dev_handle, ep=ep, intf=intf,
                              timeout=timeout)[0])

    def bulk_read(self, dev_handle: int, ep: int, intf: int, buff: array.array[int], timeout: int) -> int:
        size = len(buff) * buff.itemsize
        _, data = self._call("bulk_read", b"", timeout, handle=dev_handle, ep=ep, intf=intf, size=size,
                             timeout=timeout)
        memoryview(buff).cast("B")[:len(data)] = data[:size]
        return min(len(data), size)

    def ctrl_transfer(self, dev_handle: int, bmRequestType: int, bRequest: int, wValue: int, wIndex: int,
                      data: array.array[int], timeout: int) -> int:
        size = len(data) * data.itemsize
        inbound = bool(bmRequestType & 0x80)
        value, answer = self._call("ctrl_transfer", b"" if inbound else data.tobytes(), timeout, handle=dev_handle,
                                   bmRequestType=bmRequestType, bRequest=bRequest, wValue=wValue, wIndex=wIndex,
                                   size=size, timeout=timeout)
        if inbound:
            memoryview(data).cast("B")[:len(answer)] = answer[:size]
        return int(value)

    def clear_halt(self, dev_handle: int, ep: int) -> None:
        self._call("clear_halt", handle=dev_handle, ep=ep)

    def reset_device(self, dev_handle: int) -> None:
        self._call("reset_device", handle=dev_handle)

    def is_kernel_driver_active(self, dev_handle: int, intf: int) -> bool:
        return bool(self._call("is_kernel_driver_active", handle=dev_handle, intf=intf)[0])

    def detach_kernel_driver(self, dev_handle: int, intf: int) -> None:
        self._call("detach_kernel_driver", handle=dev_handle, intf=intf)

    def attach_kernel_driver(self, dev_handle: int, intf: int) -> None:
        self._call("attach_kernel_driver", handle=dev_handle, intf=intf)
