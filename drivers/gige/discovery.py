"""Finding GigE Vision cameras: DISCOVERY by broadcast or to one address, and ``gige://`` URLs.

``gige://ADDRESS[:PORT]`` names a camera by its IPv4 address (GVCP port 3956 unless given);
``gige://SERIAL`` by the serial number its DISCOVERY acknowledge reports, asked by broadcast on
the GVCP port, or, with ``?via=HOST[:PORT]``, of one address (a camera behind a router, or a
simulator on a loopback port).
"""

from __future__ import annotations

import ipaddress
import socket
import time
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from wavestack.drivers.errors import DeviceDisconnected, ProtocolError
from wavestack.drivers.gige import gvcp


@dataclass(frozen=True)
class GigEUrl:
    """A parsed ``gige://`` URL: an address (and port) or a serial number (and where to ask)."""

    host: str | None
    port: int
    serial: str | None
    via: tuple[str, int] | None


def _host_port(text: str, what: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":") if ":" in text else (text, "", str(gvcp.GVCP_PORT))
    try:
        number = int(port)
        ipaddress.IPv4Address(host)
    except ValueError:
        raise ValueError(f"{what} {text!r}: expected IPV4[:PORT]") from None
    if not 1 <= number <= 65535:
        raise ValueError(f"{what} {text!r}: port outside 1..65535")
    return host, number


def parse_gige_url(url: str) -> GigEUrl:
    """Split a ``gige://`` URL.

    Raises
    ------
    ValueError
        Not ``gige://ADDRESS[:PORT]`` or ``gige://SERIAL[?via=HOST[:PORT]]``.

    Example
    -------
    >>> parse_gige_url("gige://192.168.1.20")
    GigEUrl(host='192.168.1.20', port=3956, serial=None, via=None)
    >>> parse_gige_url("gige://WS-GIGE-1?via=127.0.0.1:40000").via
    ('127.0.0.1', 40000)
    """
    parts = urlsplit(url)
    if parts.scheme != "gige" or not parts.netloc or parts.path not in ("", "/"):
        raise ValueError(f"camera URL {url!r}: expected gige://ADDRESS[:PORT] or gige://SERIAL[?via=HOST[:PORT]]")
    query = parse_qs(parts.query)
    via = _host_port(query["via"][0], "via") if "via" in query else None
    try:
        host, port = _host_port(parts.netloc, "address")
    except ValueError:
        if ":" in parts.netloc or not parts.netloc.isprintable():
            raise ValueError(f"camera URL {url!r}: {parts.netloc!r} is neither IPV4[:PORT] nor a serial") from None
        return GigEUrl(None, gvcp.GVCP_PORT, parts.netloc, via)
    return GigEUrl(host, port, None, via)


def discover(targets: list[tuple[str, int]], timeout_s: float, *, device: str = "GigE Vision discovery",
             ) -> list[gvcp.DeviceInfo]:
    """DISCOVERY to each target address (broadcast addresses allowed); the devices that answered.

    The answers are collected for ``timeout_s`` seconds; each device is listed once. Replies that
    are not DISCOVERY acknowledges are ignored.
    """
    found: dict[tuple[str, str], gvcp.DeviceInfo] = {}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        sock.bind(("0.0.0.0", 0))
        packet = gvcp.encode_command(gvcp.DISCOVERY_CMD, 1, flags=gvcp.FLAG_BROADCAST_ACK)
        for target in targets:
            try:
                sock.sendto(packet, target)
            except OSError:
                continue
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            sock.settimeout(remaining)
            try:
                data, sender = sock.recvfrom(1500)
            except (TimeoutError, OSError):
                break
            try:
                ack = gvcp.parse_ack(data, device, answer=gvcp.DISCOVERY_ACK, request_id=1)
                info = gvcp.parse_discovery(ack.payload, device)
            except ProtocolError:
                continue
            found[(sender[0], info.serial)] = info
    return list(found.values())


def locate(url: GigEUrl, timeout_s: float) -> tuple[str, int, gvcp.DeviceInfo | None]:
    """Where to send GVCP for this URL: the address itself, or the one whose DISCOVERY names the serial.

    Raises
    ------
    DeviceDisconnected
        No camera with that serial answered within ``timeout_s``.
    """
    if url.host is not None:
        return url.host, url.port, None
    targets = [url.via] if url.via is not None else [("255.255.255.255", gvcp.GVCP_PORT)]
    for info in discover(targets, timeout_s, device=f"GigE camera SN {url.serial}"):
        if info.serial == url.serial:
            host = url.via[0] if url.via is not None else info.address
            port = url.via[1] if url.via is not None else gvcp.GVCP_PORT
            return host, port, info
    raise DeviceDisconnected(f"GigE camera SN {url.serial}", f"no camera with serial {url.serial!r} answered "
                             f"DISCOVERY at {targets[0][0]}:{targets[0][1]} within {timeout_s:g} s")
