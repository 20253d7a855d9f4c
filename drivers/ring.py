"""A bounded frame ring between an acquisition thread and its consumer.

Counters always add up, like pylablib's frame counters: every frame the device produced is counted
as ``acquired`` and ends up ``delivered``, ``dropped`` or still ``pending``::

    acquired == delivered + dropped + pending

and once the consumer has drained the ring, ``acquired == delivered + dropped``. A gap in the
device's frame ids (the camera overwrote frames the host never read) counts as acquired and dropped.

Two policies:

``NEWEST_ONLY`` (closed loops)
    The consumer always gets the newest frame; a new frame supersedes the pending one, which is
    dropped at once (it could never be delivered), so at most one frame is held whatever the
    capacity. A slow consumer sees fresh data, never a backlog, and a stalled one holds one frame,
    not ``capacity`` (issue 13's soak: a station stalled by a PLC fault held two 10 MB phase sets).
``OLDEST_FIRST`` (recording)
    First in, first out; a full ring drops the *incoming* frame, so what is kept is contiguous from
    the oldest pending frame.
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar

from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, renewed

T = TypeVar("T")
logger = logging.getLogger(__name__)


class WaitTimeout(DeviceTimeout):
    """:meth:`FrameRing.get` waited its whole timeout and no frame came (the ring is open and empty).

    A consumer that waits in slices tells it from a device's own timeout handed over by
    :meth:`FrameRing.close` (which is a plain :class:`DeviceTimeout`).
    """


class FrameLost(DeviceError):
    """A frame the consumer waits for will never come: the producer reported it lost (e.g. a damaged block).

    Raised by :meth:`FrameRing.get` only to a caller that asked for it (``fail_after_loss``), so
    a triggered acquisition learns at once that its frame is gone instead of waiting its timeout.
    """


class RingPolicy(enum.Enum):
    """Which frames a full or lagging ring gives up."""

    NEWEST_ONLY = "newest"
    OLDEST_FIRST = "oldest"


@dataclass(frozen=True)
class RingCounters:
    """A consistent snapshot of a ring's counters (taken under its lock).

    Attributes
    ----------
    acquired
        Frames the device produced, including those lost in frame-id gaps.
    delivered
        Frames handed to the consumer.
    dropped
        Frames given up: overwritten, superseded by a newer one, refused when full, or never received.
    dropped_in_gaps
        The part of ``dropped`` inferred from gaps in the device's frame ids.
    pending
        Frames waiting in the ring.
    """

    acquired: int
    delivered: int
    dropped: int
    dropped_in_gaps: int
    pending: int


class FrameRing(Generic[T]):
    """Bounded, thread-safe hand-over of frames from one producer to one consumer.

    Parameters
    ----------
    capacity
        Most frames held at once (>= 1); memory stays bounded by ``capacity`` frames (one frame
        with ``NEWEST_ONLY``).
    policy
        :class:`RingPolicy`.
    name
        The device the frames come from, used in error messages.
    """

    def __init__(self, capacity: int, policy: RingPolicy, *, name: str = "frame ring") -> None:
        if capacity < 1:
            raise ValueError(f"FrameRing capacity must be >= 1, got {capacity}")
        self._capacity = capacity
        self._policy = RingPolicy(policy)
        self._name = name
        self._items: deque[T] = deque()
        self._condition = threading.Condition()
        self._acquired = 0
        self._delivered = 0
        self._dropped = 0
        self._dropped_in_gaps = 0
        self._last_frame_id: int | None = None
        self._closed = False
        self._close_error: DeviceError | None = None
        self._losses = 0  # frames the producer reported lost (note_loss)

    @property
    def policy(self) -> RingPolicy:
        return self._policy

    @property
    def capacity(self) -> int:
        return self._capacity

    def put(self, item: T, frame_id: int | None = None) -> None:
        """Add a frame; never blocks.

        Parameters
        ----------
        item
            The frame.
        frame_id
            The device's frame id, if it has one: a jump of more than one counts the missing frames
            as acquired and dropped. A smaller id (the device restarted its count) starts afresh.
        """
        with self._condition:
            if self._closed:
                raise DeviceDisconnected(self._name, "frame ring is closed; no frames are accepted after close()")
            if frame_id is not None:
                if self._last_frame_id is not None and frame_id > self._last_frame_id + 1:
                    missing = frame_id - self._last_frame_id - 1
                    self._acquired += missing
                    self._dropped += missing
                    self._dropped_in_gaps += missing
                elif self._last_frame_id is not None and frame_id <= self._last_frame_id:
                    logger.info("%s: frame id went from %d to %d; counting afresh",
                                self._name, self._last_frame_id, frame_id)
                self._last_frame_id = frame_id
            self._acquired += 1
            if self._policy is RingPolicy.NEWEST_ONLY:
                # a pending frame superseded now can never be delivered: dropped at once, not held
                # until the next read (a stalled consumer would keep ``capacity`` frames for nothing)
                self._dropped += len(self._items)
                self._items.clear()
            elif len(self._items) >= self._capacity:
                self._dropped += 1
                return  # keep what is pending contiguous; the incoming frame is the one given up
            self._items.append(item)
            self._condition.notify()

    def note_loss(self) -> None:
        """The producer lost a frame (damaged, incomplete): wake a consumer that asked to hear of it.

        Counting is left to the frame ids (a gap counts the lost frame acquired and dropped).
        """
        with self._condition:
            self._losses += 1
            self._condition.notify_all()

    @property
    def losses(self) -> int:
        """Frames the producer reported lost so far (a mark for ``get(..., fail_after_loss=)``)."""
        with self._condition:
            return self._losses

    def get(self, timeout_s: float, *, fail_after_loss: int | None = None) -> T:
        """Take the next frame by the ring's policy.

        Parameters
        ----------
        timeout_s
            Longest wait in seconds (>= 0).
        fail_after_loss
            A value of :attr:`losses` taken earlier (before a trigger): while the ring is empty,
            a loss reported since then raises :class:`FrameLost` at once.

        Raises
        ------
        WaitTimeout
            No frame within ``timeout_s`` (a :class:`DeviceTimeout`).
        DeviceError
            The ring was closed and is empty: the error it was closed with (e.g.
            ``DeviceDisconnected`` after an unplug), or ``DeviceDisconnected`` for a plain close.
        FrameLost
            See ``fail_after_loss``.
        """
        if timeout_s < 0:
            raise ValueError(f"timeout_s must be >= 0, got {timeout_s}")
        deadline = time.monotonic() + timeout_s
        with self._condition:
            while not self._items:
                if self._closed:
                    if self._close_error is not None:  # a new object each time: no growing traceback, no cycle
                        raise renewed(self._close_error)
                    raise DeviceDisconnected(self._name, "frame ring closed; no more frames")
                if fail_after_loss is not None and self._losses > fail_after_loss:
                    raise FrameLost(self._name, f"{self._losses - fail_after_loss} frame(s) lost on the way "
                                                "(damaged or incomplete block); expected a whole frame")
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise WaitTimeout(self._name, f"expected a frame within {timeout_s:g} s, got none")
                self._condition.wait(remaining)
            if self._policy is RingPolicy.NEWEST_ONLY:
                superseded = len(self._items) - 1
                self._dropped += superseded
                item = self._items.pop()
                self._items.clear()
            else:
                item = self._items.popleft()
            self._delivered += 1
            return item

    def close(self, error: DeviceError | None = None) -> None:
        """Accept no more frames; a consumer drains what is pending, then gets ``error``.

        Idempotent; the first error given wins.
        """
        with self._condition:
            self._closed = True
            if self._close_error is None:
                self._close_error = error
            self._condition.notify_all()

    def discard_pending(self) -> int:
        """Drop every pending frame (counted as dropped); returns how many."""
        with self._condition:
            count = len(self._items)
            self._dropped += count
            self._items.clear()
            return count

    @property
    def closed(self) -> bool:
        with self._condition:
            return self._closed

    def counters(self) -> RingCounters:
        """A consistent snapshot of the counters."""
        with self._condition:
            return RingCounters(self._acquired, self._delivered, self._dropped, self._dropped_in_gaps,
                                len(self._items))
