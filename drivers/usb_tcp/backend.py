"""A pyusb backend whose USB transfers travel over TCP to a USB bus on another host (``usbtcp://``).

A USB3 Vision camera is a USB device of the host it is plugged into; :class:`UsbTcpBackend` lets
the unchanged driver (:class:`~wavestack.drivers.u3v.U3VCamera`) reach a camera served by another
process, in the manner of USB/IP but in user space: every pyusb backend call is one request and
one reply (:mod:`.protocol`) on a :class:`~wavestack.drivers.link.ByteLink`. It exists for the
remote alignment-bench simulator (``wavestack sim align-bench``); a camera on a local bus needs none.

Each thread gets its own connection (the stream thread's long bulk reads never hold up the control
channel); all of them join one session, in which the backend's device handles live. Every call
has a deadline: a transfer its own timeout plus ``margin_s``, anything else ``io_timeout_s``. A
connection that fails, a server that does not answer by the deadline, reads as an unplugged device
(``ENODEV``); a reply of the wrong shape as an I/O error (``EIO``; the camera driver's
``ProtocolError``); enumeration on an unreachable server finds no device.
"""

from __future__ import annotations

import array
import errno
import logging
import threading
import time
import urllib.parse
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core

from wavestack.drivers.errors import DeviceError
from wavestack.drivers.link import ByteLink
from wavestack.drivers.usb_tcp.protocol import (
    HEAD,
    MAX_HEADER_BYTES,
    MAX_PAYLOAD_BYTES,
    MalformedReply,
    RemoteIndexError,
    RemoteUsbError,
    check_reply,
    encode_request,
    reply_framing,
)

__all__ = ["UsbTcpBackend", "parse_usbtcp_url"]

logger = logging.getLogger(__name__)


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
    io_timeout_s : float
        Deadline of a call that is not a transfer (connect, enumerate, descriptors, open, claim), s.
    margin_s : float
        Added to a transfer's own timeout for its reply to arrive, s.

    Example
    -------
    >>> backend = UsbTcpBackend("127.0.0.1", 1)  # nothing listens on port 1: no device on that bus
    >>> list(backend.enumerate_devices())
    []
    """

    def __init__(self, host: str, port: int, *, io_timeout_s: float = 2.0, margin_s: float = 1.0) -> None:
        if not (io_timeout_s > 0 and margin_s >= 0):
            raise ValueError(f"io_timeout_s must be > 0 and margin_s >= 0, got {io_timeout_s!r}, {margin_s!r}")
        self._address = (host, int(port))
        self._io_timeout_s, self._margin_s = float(io_timeout_s), float(margin_s)
        self._name = f"USB server {host}:{int(port)}"
        self._local = threading.local()
        self._lock = threading.Lock()
        self._links: list[ByteLink] = []
        self._session: str | None = None
        self._open_handles = 0

    # --- the connection -----------------------------------------------------------------------
    def _link(self, deadline: float) -> ByteLink:
        link: ByteLink | None = getattr(self._local, "link", None)
        if link is not None:
            return link
        host, port = self._address
        link = ByteLink(f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}", lambda: self._name,
                        max_reply_bytes=HEAD.size + MAX_HEADER_BYTES + MAX_PAYLOAD_BYTES, poll_s=0.05)
        link.open(max(1e-3, deadline - time.monotonic()))
        try:
            with self._lock:
                session = self._session
            reply = link.exchange(encode_request("hello", {"session": session}), reply_framing, deadline,
                                  during="hello")
            outcome = check_reply("hello", reply)
            if not isinstance(outcome, tuple):
                raise MalformedReply(f"hello answered {outcome}")
        except BaseException:
            link.close()
            raise
        with self._lock:
            if self._session is not None and outcome[0] != self._session:
                logger.info("%s: the session ended on the server; the handles it held are gone", self._name)
            self._session = outcome[0]
            self._links.append(link)
        self._local.link = link
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
        """Close every connection (a later call opens new ones, in a new session)."""
        with self._lock:
            links, self._links, self._session = self._links, [], None
        for link in links:
            link.close()
        self._local = threading.local()

    def _call(self, op: str, payload: bytes = b"", timeout_ms: int | None = None, *, reply_size: int | None = None,
              **args: Any) -> tuple[Any, bytes]:
        """One request and its checked reply (module notes for the errors raised)."""
        budget_s = timeout_ms / 1000.0 + self._margin_s if timeout_ms else self._io_timeout_s
        request = encode_request(op, args, payload)
        for attempt in range(2):  # a kept connection the server dropped since is retried once on a new one
            reused = getattr(self._local, "link", None) is not None
            deadline = time.monotonic() + budget_s
            try:
                frame = self._link(deadline).exchange(request, reply_framing, deadline, during=op)
                outcome = check_reply(op, frame, size=reply_size, sent=len(payload) if op == "bulk_write" else None)
                break
            except MalformedReply as error:
                self._drop_link()
                raise usb.core.USBError(f"Input/Output Error: {self._name} sent a malformed reply to {op} "
                                        f"({error})", -1, errno.EIO) from None
            except (DeviceError, OSError) as error:  # refused, reset, closed, no reply by the deadline
                self._drop_link()
                retry = reused and attempt == 0 and not isinstance(error, TimeoutError)
                if not retry:
                    raise usb.core.USBError(f"No such device (it may have been disconnected): {error}", -4,
                                            errno.ENODEV) from None
        if isinstance(outcome, RemoteUsbError):
            cls = usb.core.USBTimeoutError if outcome.errno == errno.ETIMEDOUT else usb.core.USBError
            raise cls(outcome.message, outcome.backend_code, outcome.errno)
        if isinstance(outcome, RemoteIndexError):
            raise IndexError(outcome.message)
        return outcome

    # --- enumeration and descriptors ----------------------------------------------------------
    def enumerate_devices(self) -> Iterator[_Device]:
        try:
            found, _ = self._call("enumerate_devices")
        except usb.core.USBError as error:
            logger.info("%s: no device enumerated (%s)", self._name, error)
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
        count, data = self._call("bulk_read", b"", timeout, reply_size=size, handle=dev_handle, ep=ep, intf=intf,
                                 size=size, timeout=timeout)
        memoryview(buff).cast("B")[:count] = data
        return int(count)

    def ctrl_transfer(self, dev_handle: int, bmRequestType: int, bRequest: int, wValue: int, wIndex: int,
                      data: array.array[int], timeout: int) -> int:
        size = len(data) * data.itemsize
        inbound = bool(bmRequestType & 0x80)
        value, answer = self._call("ctrl_transfer", b"" if inbound else data.tobytes(), timeout,
                                   reply_size=size if inbound else None, handle=dev_handle,
                                   bmRequestType=bmRequestType, bRequest=bRequest, wValue=wValue, wIndex=wIndex,
                                   size=size, timeout=timeout)
        if inbound:
            memoryview(data).cast("B")[:value] = answer
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
