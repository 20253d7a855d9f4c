"""One browser's queue: a bounded queue of size 1 where the newest update wins and replaced ones are counted.

The server puts every update into every browser's slot; each browser's sender takes from its own
slot when its previous message has gone out. A browser that reads slowly (or not at all) only
makes its own slot replace updates, counted as dropped for it: the station and the other
browsers never wait for it. All on the server's event loop (no locks).
"""

from __future__ import annotations

import asyncio
from typing import Generic, TypeVar

__all__ = ["LatestSlot"]

T = TypeVar("T")


class LatestSlot(Generic[T]):
    """A queue of size 1: :meth:`put` replaces what is waiting, :meth:`get` waits for the newest.

    Example
    -------
    >>> async def demo():
    ...     slot = LatestSlot()
    ...     slot.put(1); slot.put(2)
    ...     return await slot.get(), slot.dropped
    >>> asyncio.run(demo())
    (2, 1)
    """

    def __init__(self) -> None:
        self._item: T | None = None
        self._ready = asyncio.Event()
        self.dropped = 0  # updates replaced before they were taken
        self.taken = 0

    @property
    def waiting(self) -> bool:
        """An item is waiting to be taken."""
        return self._item is not None

    def put(self, item: T) -> None:
        """Offer ``item``; one still waiting is replaced and counted dropped."""
        if self._item is not None:
            self.dropped += 1
        self._item = item
        self._ready.set()

    async def get(self) -> T:
        """The newest item, waiting for one if none is waiting."""
        while self._item is None:
            self._ready.clear()
            await self._ready.wait()
        item, self._item = self._item, None
        self._ready.clear()
        self.taken += 1
        return item
