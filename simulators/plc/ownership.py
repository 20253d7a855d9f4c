"""Who may write to the simulated PLC: one owner connection, as data (pure).

Re-implemented from the register map's access model (docs/instruments.md, "Who may write"), not
from the driver. The PLC serves any number of Modbus/TCP connections; all may read, but the
heartbeat, the command block, the job block and the display block take writes from one connection
only, the *owner*, and the re-arm register from anyone (the operator's monitor link re-arms a
tripped watchdog). Ownership goes to the first connection that claims it and lasts until the watchdog
trips (or the PLC is power-cycled): a second connection can neither feed the watchdog of a host
that died nor command the machine.

A map with an owner block (four registers, written whole with FC16, read back as zeros) claims
with a token: a connection writing a non-zero token becomes the owner when there is none, or
takes over the owner's place when it writes the owner's own token (the same host after a
reconnect: a restart of the PLC's Modbus service, a reply lost and the socket closed). Any other
token is refused. A map without one gives ownership to the first connection that writes the
heartbeat; nobody else can take it until the watchdog trips, so a reconnect trips it.

============================  =================================================================
event                         effect
============================  =================================================================
claim(token), no owner        this connection owns, with that token
claim(the owner's token)      this connection owns (the owner's earlier connection loses it)
claim(another token)          refused, nothing changes
first heartbeat, no token map this connection owns (no token)
the owner's connection closes the token stays; no connection holds it until a claim re-attaches
trip, power cycle             nobody owns
============================  =================================================================
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["NOBODY", "Ownership", "claim", "closed", "first_heartbeat", "owns"]

Token = tuple[int, ...]


@dataclass(frozen=True)
class Ownership:
    """The owner's token (None: nobody owns; empty: owned by a map without an owner block) and the
    connection that holds it now (None: none attached)."""

    token: Token | None = None
    connection: int | None = None


NOBODY = Ownership()


def claim(ownership: Ownership, connection: int, token: Token) -> tuple[Ownership, bool]:
    """A connection writes ``token`` to the owner block; the new ownership and whether it was taken.

    Examples
    --------
    >>> first, taken = claim(NOBODY, 1, (7, 7, 7, 7))
    >>> taken, claim(first, 2, (8, 8, 8, 8))[1], claim(first, 3, (7, 7, 7, 7))
    (True, False, (Ownership(token=(7, 7, 7, 7), connection=3), True))
    """
    if not any(token):
        return ownership, False
    if ownership.token is None or ownership.token == token:
        return Ownership(token, connection), True
    return ownership, False


def first_heartbeat(ownership: Ownership, connection: int) -> Ownership:
    """A map without an owner block: the first connection that writes the heartbeat owns."""
    return Ownership((), connection) if ownership.token is None else ownership


def owns(ownership: Ownership, connection: int) -> bool:
    """Whether ``connection`` may write the heartbeat, command, job and display blocks."""
    return ownership.connection is not None and ownership.connection == connection


def closed(ownership: Ownership, connection: int) -> Ownership:
    """``connection`` closed: the owner's place is empty until its token claims it again."""
    return Ownership(ownership.token, None) if ownership.connection == connection else ownership
