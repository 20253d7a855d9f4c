"""Where a server a command starts may listen: loopback unless the operator allows another interface.

The simulators' protocols (Modbus/TCP, GCS, USB over TCP) and the web view's page have no
authentication, so the commands that serve them (``wavestack sim ...``, ``--web``) refuse a
non-loopback address without ``--allow-remote``.
"""

from __future__ import annotations

import ipaddress

__all__ = ["check_bind", "is_loopback"]


def is_loopback(host: str) -> bool:
    """Whether ``host`` is ``localhost`` or a loopback IP literal (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_bind(host: str, port: int, allow_remote: bool, *, simulator: str, protocol: str) -> None:
    """Refuse a non-loopback ``host`` without ``allow_remote``, and a port outside 0..65535 (ValueError).

    A simulator's protocol has no authentication: on another interface anyone who reaches the
    port could command the (simulated) machine.
    """
    if not is_loopback(host) and not allow_remote:
        raise ValueError(f"refusing to serve {simulator} on {host!r}: {protocol} has no authentication, "
                         "so only a loopback address (127.0.0.1, ::1, localhost) is allowed; pass --allow-remote "
                         "to serve on another interface")
    if not 0 <= port <= 65535:
        raise ValueError(f"port must be 0..65535 (0 = any free port), got {port}")
