"""Which ``Host`` a request to the web view may name: loopback, the bound address, this machine (pure).

A page on another site can make the browser send requests to the station through DNS rebinding:
its own name, re-pointed at 127.0.0.1, lands on our port with ``Host: evil.example:8765``. The same
origin policy lets that page read the replies, since to the browser they come from its own site.
The server therefore answers only requests whose ``Host`` names this machine as the user would:
``localhost`` or a loopback address, the address or name the server was bound to (``--web-host``),
this machine's own host names, or the address the connection actually arrived on (a browser
pointed at the station's IP). Any other name is refused (HTTP 421).
"""

from __future__ import annotations

import ipaddress
import socket

__all__ = ["host_name", "machine_names", "names_allowed"]

_LOOPBACK_NAMES = frozenset({"localhost", "localhost.localdomain", "ip6-localhost"})


def host_name(header: str | None) -> str | None:
    """The name (or address) in a ``Host`` header, lower case, without port, brackets or a final dot.

    Examples
    --------
    >>> host_name("127.0.0.1:8765"), host_name("[::1]:8765"), host_name("Station.Local."), host_name(None)
    ('127.0.0.1', '::1', 'station.local', None)
    """
    if not header:
        return None
    text = header.strip().lower()
    if text.startswith("["):
        end = text.find("]")
        return text[1:end] if end > 0 else None
    name = text.rsplit(":", 1)[0] if text.count(":") == 1 else text
    return name.rstrip(".") or None


def machine_names() -> frozenset[str]:
    """This machine's own host names (``gethostname`` and its fully qualified name), lower case."""
    names = {socket.gethostname(), socket.getfqdn()}
    return frozenset(n.lower().rstrip(".") for n in names if n)


def names_allowed(name: str | None, *, bound: str, arrived_on: str | None, machine: frozenset[str]) -> bool:
    """Whether a request whose ``Host`` names ``name`` may be answered (module notes).

    Parameters
    ----------
    name : str or None
        From :func:`host_name`.
    bound : str
        The address or name the server listens on.
    arrived_on : str or None
        The local address the request's connection arrived on.
    machine : frozenset of str
        From :func:`machine_names`.

    Examples
    --------
    >>> names_allowed("localhost", bound="127.0.0.1", arrived_on="127.0.0.1", machine=frozenset())
    True
    >>> names_allowed("evil.example", bound="127.0.0.1", arrived_on="127.0.0.1", machine=frozenset())
    False
    >>> names_allowed("10.0.0.5", bound="0.0.0.0", arrived_on="10.0.0.5", machine=frozenset())
    True
    """
    if name is None:
        return False
    if name in _LOOPBACK_NAMES or name in machine or name == host_name(bound) or name == arrived_on:
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False
