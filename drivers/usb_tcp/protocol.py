"""The USB-over-TCP wire format, host side (pure): requests encoded, replies framed and checked.

Both ways a message is a 4-byte big-endian length of a UTF-8 JSON header, a 4-byte length of a
binary payload, the header, the payload. A request header is ``{"op": NAME, "args": {...}}``: one
pyusb backend call (:data:`OPERATIONS`), devices and handles as integer references the server
hands out. A reply header is exactly one of ``{"value": ...}``, ``{"usb_error": [message,
backend_code, errno]}`` or ``{"index_error": message}``.

A connection first says ``hello`` with the session it belongs to (None for a new one); the server
answers the session's id (a new one when that session is gone). Every connection of one host's
backend joins one session, and a device handle is valid only in the session that opened it: a
second peer can neither read the first one's stream nor close its handles. The first session
that claims an interface of a device owns the device until it ends (the server's rule, see
:mod:`wavestack.simulators.usb_tcp`).

Bounds: a header holds at most :data:`MAX_HEADER_BYTES`, a payload (a write's data, a read's
answer, the size a read may ask for) at most :data:`MAX_PAYLOAD_BYTES`. :func:`check_reply` checks
that a reply has the shape its operation allows (types, a read's length within the size asked
for), so a malformed reply is an error here, never an exception deep inside pyusb.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["MAX_HEADER_BYTES", "MAX_PAYLOAD_BYTES", "OPERATIONS", "MalformedReply", "RemoteIndexError",
           "RemoteUsbError", "ReplyFrame", "check_reply", "encode_request", "reply_framing"]

HEAD = struct.Struct(">II")
#: Largest JSON header either way, bytes.
MAX_HEADER_BYTES = 1 << 16
#: Largest payload either way, bytes (a full frame of a large camera in one bulk read).
MAX_PAYLOAD_BYTES = 32 << 20


class MalformedReply(ValueError):
    """A reply that does not have the shape the wire format allows for its request."""


@dataclass(frozen=True)
class ReplyFrame:
    """One framed reply: its decoded JSON header and its payload."""

    header: object
    payload: bytes


@dataclass(frozen=True)
class RemoteUsbError:
    """The server's backend raised ``usb.core.USBError(message, backend_code, errno)``."""

    message: str
    backend_code: int
    errno: int | None


@dataclass(frozen=True)
class RemoteIndexError:
    """The server's backend raised ``IndexError`` (pyusb's "no such descriptor")."""

    message: str


def encode_request(op: str, args: Mapping[str, Any], payload: bytes = b"") -> bytes:
    """One request message.

    Raises
    ------
    ValueError
        An unknown operation, or a header or payload over the bounds.

    Examples
    --------
    >>> encode_request("hello", {"session": None})[:8]
    b'\\x00\\x00\\x00,\\x00\\x00\\x00\\x00'
    """
    if op not in OPERATIONS:
        raise ValueError(f"unknown operation {op!r}")
    body = json.dumps({"op": op, "args": dict(args)}).encode()
    if len(body) > MAX_HEADER_BYTES or len(payload) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"request of {len(body)} + {len(payload)} bytes exceeds {MAX_HEADER_BYTES} + "
                         f"{MAX_PAYLOAD_BYTES}")
    return HEAD.pack(len(body), len(payload)) + body + payload


def reply_framing(buffer: bytearray) -> tuple[ReplyFrame | None, bytes | bytearray]:
    """The first complete reply in ``buffer`` and the bytes after it, or ``(None, buffer)``.

    Raises
    ------
    MalformedReply
        Declared sizes over the bounds, or a header that is not UTF-8 JSON.

    Examples
    --------
    >>> frame, rest = reply_framing(bytearray(b"\\x00\\x00\\x00\\x0c\\x00\\x00\\x00\\x01" + b'{"value": 3}' + b"x"))
    >>> frame.header, frame.payload, rest
    ({'value': 3}, b'x', bytearray(b''))
    """
    if len(buffer) < HEAD.size:
        return None, buffer
    size, data_size = HEAD.unpack_from(buffer)
    if size > MAX_HEADER_BYTES or data_size > MAX_PAYLOAD_BYTES:
        raise MalformedReply(f"a reply of {size} + {data_size} bytes; expected at most {MAX_HEADER_BYTES} + "
                             f"{MAX_PAYLOAD_BYTES}")
    end = HEAD.size + size + data_size
    if len(buffer) < end:
        return None, buffer
    try:
        header = json.loads(bytes(buffer[HEAD.size:HEAD.size + size]).decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        raise MalformedReply(f"a reply header that is not UTF-8 JSON ({error})") from None
    return ReplyFrame(header, bytes(buffer[HEAD.size + size:end])), buffer[end:]


def check_reply(op: str, frame: ReplyFrame, *, size: int | None = None,
                sent: int | None = None) -> tuple[Any, bytes] | RemoteUsbError | RemoteIndexError:
    """What a reply to ``op`` says: ``(value, payload)``, or the error the server's backend raised.

    Parameters
    ----------
    op : str
        The request's operation.
    frame : ReplyFrame
    size : int, optional
        Bytes a read asked for (``bulk_read``, an inbound ``ctrl_transfer``): the payload holds
        at most that many, and exactly as many as the value says.
    sent : int, optional
        Bytes a write sent: the count written is at most that.

    Raises
    ------
    MalformedReply
        Anything else.

    Examples
    --------
    >>> check_reply("get_configuration", ReplyFrame({"value": 1}, b""))
    (1, b'')
    >>> check_reply("get_configuration", ReplyFrame({"value": "1"}, b""))
    Traceback (most recent call last):
    ...
    wavestack.drivers.usb_tcp.protocol.MalformedReply: get_configuration: the reply {'value': '1'} is not what it allows
    """
    header, payload = frame.header, frame.payload
    if not isinstance(header, dict) or len(header) != 1:
        raise MalformedReply(f"{op}: expected a reply object with one of value, usb_error, index_error; "
                             f"got {header!r:.80}")
    if "usb_error" in header:
        error = header["usb_error"]
        if not (isinstance(error, list) and len(error) == 3 and isinstance(error[0], str) and _int(error[1])
                and (error[2] is None or _int(error[2]))):
            raise MalformedReply(f"{op}: a usb_error must be [message, backend_code, errno], got {error!r:.80}")
        return RemoteUsbError(error[0], error[1], error[2])
    if "index_error" in header:
        if not isinstance(header["index_error"], str):
            raise MalformedReply(f"{op}: an index_error must be a message, got {header['index_error']!r:.80}")
        return RemoteIndexError(header["index_error"])
    value = header.get("value", _MISSING)
    check = OPERATIONS.get(op)
    if check is None or value is _MISSING or not check(value):
        raise MalformedReply(f"{op}: the reply {header!r:.80} is not what it allows")
    if size is not None and not (value == len(payload) <= size):
        raise MalformedReply(f"{op}: {value!r} bytes said, {len(payload)} sent, {size} asked for")
    if size is None and payload:
        raise MalformedReply(f"{op}: a payload of {len(payload)} bytes; expected none")
    if sent is not None and not 0 <= value <= sent:
        raise MalformedReply(f"{op}: {value} bytes written of {sent} sent")
    return value, payload


_MISSING = object()


def _int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _descriptor(value: object) -> bool:
    """A descriptor's fields: names to None, an integer, or a list of bytes (extra descriptors, port numbers)."""
    return isinstance(value, dict) and bool(value) and all(
        isinstance(key, str) and (item is None or _int(item)
                                  or (isinstance(item, list) and all(_int(b) and 0 <= b < 256 for b in item)))
        for key, item in value.items()) and all(_int(value.get(k)) for k in ("bLength", "bDescriptorType"))


def _devices(value: object) -> bool:
    return isinstance(value, list) and all(
        isinstance(item, list) and len(item) == 2 and _int(item[0]) and _descriptor(item[1]) for item in value)


def _none(value: object) -> bool:
    return value is None


def _count(value: object) -> bool:
    return _int(value) and 0 <= value <= MAX_PAYLOAD_BYTES  # type: ignore[operator]


#: Every operation and the value its reply may carry.
OPERATIONS: dict[str, Callable[[object], bool]] = {
    "hello": lambda v: isinstance(v, str) and 0 < len(v) <= 64,
    "enumerate_devices": _devices,
    "get_configuration_descriptor": _descriptor, "get_interface_descriptor": _descriptor,
    "get_endpoint_descriptor": _descriptor,
    "open_device": _int, "close_device": _none, "set_configuration": _none, "get_configuration": _int,
    "set_interface_altsetting": _none, "claim_interface": _none, "release_interface": _none,
    "bulk_write": _count, "bulk_read": _count, "ctrl_transfer": _count,
    "clear_halt": _none, "reset_device": _none, "is_kernel_driver_active": lambda v: isinstance(v, bool),
    "detach_kernel_driver": _none, "attach_kernel_driver": _none,
}
