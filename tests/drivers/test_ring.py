"""The bounded frame ring: policies, counters that add up, and a producer that outruns its consumer."""

from __future__ import annotations

import gc
import threading
import time
import weakref

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.drivers import DeviceDisconnected, DeviceTimeout, FrameRing, RingPolicy


def _assert_adds_up(ring: FrameRing) -> None:
    c = ring.counters()
    assert c.acquired == c.delivered + c.dropped + c.pending, c
    assert 0 <= c.pending <= ring.capacity


def test_newest_only_delivers_the_newest_and_drops_the_rest() -> None:
    ring: FrameRing[int] = FrameRing(3, RingPolicy.NEWEST_ONLY)
    for frame_id in range(5):
        ring.put(frame_id, frame_id=frame_id)
    assert ring.get(0.0) == 4
    c = ring.counters()
    # 5 acquired: 0 and 1 overwritten when full, 2 and 3 superseded by 4 at the read.
    assert (c.acquired, c.delivered, c.dropped, c.pending) == (5, 1, 4, 0)


def test_oldest_first_keeps_order_and_refuses_when_full() -> None:
    ring: FrameRing[int] = FrameRing(3, RingPolicy.OLDEST_FIRST)
    for frame_id in range(5):
        ring.put(frame_id, frame_id=frame_id)
    assert [ring.get(0.0) for _ in range(3)] == [0, 1, 2]
    c = ring.counters()
    assert (c.acquired, c.delivered, c.dropped, c.pending) == (5, 3, 2, 0)


def test_gaps_in_frame_ids_count_as_acquired_and_dropped() -> None:
    ring: FrameRing[int] = FrameRing(8, RingPolicy.OLDEST_FIRST)
    for frame_id in (10, 11, 15, 16):  # 12, 13, 14 never reached the host
        ring.put(frame_id, frame_id=frame_id)
    c = ring.counters()
    assert (c.acquired, c.dropped, c.dropped_in_gaps, c.pending) == (7, 3, 3, 4)


def test_a_restarted_frame_count_is_not_a_gap() -> None:
    ring: FrameRing[int] = FrameRing(8, RingPolicy.OLDEST_FIRST)
    for frame_id in (5, 6, 0, 1):
        ring.put(frame_id, frame_id=frame_id)
    assert ring.counters().dropped == 0


def test_newest_only_holds_one_frame_while_the_consumer_stalls() -> None:
    class Set:  # stands for a phase set of five 2 MB frames
        pass

    ring: FrameRing[Set] = FrameRing(3, RingPolicy.NEWEST_ONLY)
    first = Set()
    gone = weakref.ref(first)
    ring.put(first)
    del first
    for _ in range(3):
        ring.put(Set())
    c = ring.counters()
    # the superseded frames are dropped and freed when the newer one arrives, not at the next read
    assert (c.acquired, c.delivered, c.dropped, c.pending) == (4, 0, 3, 1)
    assert gone() is None
    assert isinstance(ring.get(0.0), Set) and ring.counters().pending == 0


def test_get_times_out_with_a_typed_error_naming_the_device() -> None:
    ring: FrameRing[int] = FrameRing(2, RingPolicy.NEWEST_ONLY, name="camera 42")
    with pytest.raises(DeviceTimeout, match="camera 42"):
        ring.get(0.01)


def test_close_lets_the_consumer_drain_then_raises_the_close_error_once_per_call() -> None:
    ring: FrameRing[int] = FrameRing(4, RingPolicy.OLDEST_FIRST, name="cam")
    ring.put(1)
    ring.close(DeviceDisconnected("cam", "unplugged"))
    assert ring.get(0.0) == 1
    with pytest.raises(DeviceDisconnected, match="unplugged"):
        ring.get(0.0)
    with pytest.raises(DeviceDisconnected):
        ring.put(2)


def test_the_close_error_raised_again_holds_no_caller_alive() -> None:
    """Each raise is a new error: the kept one's traceback does not grow and no cycle keeps the
    callers' locals (a set of camera frames in the station) until the cyclic collector runs."""
    ring: FrameRing[int] = FrameRing(4, RingPolicy.OLDEST_FIRST, name="cam")
    ring.close(DeviceDisconnected("cam", "unplugged"))

    class Frames:  # stands for a caller's set of images
        pass

    def caller() -> weakref.ref:
        frames = Frames()
        try:
            ring.get(0.0)
        except DeviceDisconnected:
            pass
        return weakref.ref(frames)

    enabled = gc.isenabled()
    gc.disable()
    try:
        kept = [caller() for _ in range(3)]
        assert all(ref() is None for ref in kept)  # freed by reference counts alone
    finally:
        if enabled:
            gc.enable()
    errors = []
    for _ in range(2):
        with pytest.raises(DeviceDisconnected, match="unplugged") as caught:
            ring.get(0.0)
        errors.append(caught.value)
    assert errors[0] is not errors[1] and errors[0].device == "cam"


def test_close_wakes_a_waiting_consumer() -> None:
    ring: FrameRing[int] = FrameRing(4, RingPolicy.NEWEST_ONLY)
    errors: list[BaseException] = []

    def consume() -> None:
        try:
            ring.get(30.0)
        except DeviceDisconnected as error:
            errors.append(error)

    consumer = threading.Thread(target=consume)
    consumer.start()
    time.sleep(0.05)
    ring.close()
    consumer.join(5.0)
    assert not consumer.is_alive() and len(errors) == 1


@settings(max_examples=200, deadline=None)
@given(policy=st.sampled_from(list(RingPolicy)), capacity=st.integers(1, 5),
       operations=st.lists(st.one_of(st.integers(0, 3), st.just("get")), max_size=60))
def test_counters_add_up_after_any_sequence(policy: RingPolicy, capacity: int, operations: list) -> None:
    ring: FrameRing[int] = FrameRing(capacity, policy)
    frame_id = 0
    first_id: int | None = None
    delivered: list[int] = []
    for op in operations:
        if op == "get":
            try:
                delivered.append(ring.get(0.0))
            except DeviceTimeout:
                pass
        else:
            frame_id += 1 + op  # op > 0 leaves a gap of op frames
            first_id = frame_id if first_id is None else first_id
            ring.put(frame_id, frame_id=frame_id)
        _assert_adds_up(ring)
    assert delivered == sorted(delivered)  # both policies deliver in device order
    assert ring.counters().delivered == len(delivered)
    # Frames before the first one seen are unknown to the host, so they are not counted.
    assert ring.counters().acquired == (0 if first_id is None else frame_id - first_id + 1)


@pytest.mark.parametrize("policy", list(RingPolicy))
def test_overrun_producer_outruns_consumer_memory_stays_bounded(policy: RingPolicy) -> None:
    ring: FrameRing[bytes] = FrameRing(4, policy)
    stop = threading.Event()
    max_pending = 0

    def produce() -> None:
        frame_id = 0
        while not stop.is_set():
            ring.put(bytes(1024), frame_id=frame_id)
            frame_id += 1

    producer = threading.Thread(target=produce)
    producer.start()
    deadline = time.monotonic() + 1.5
    delivered = 0
    try:
        while time.monotonic() < deadline:
            ring.get(1.0)
            delivered += 1
            max_pending = max(max_pending, ring.counters().pending)
            time.sleep(0.002)  # a slow consumer
    finally:
        stop.set()
        producer.join(5.0)
    while True:
        try:
            ring.get(0.0)
            delivered += 1
        except DeviceTimeout:
            break
    c = ring.counters()
    assert max_pending <= 4
    assert c.pending == 0 and c.delivered == delivered
    assert c.acquired == c.delivered + c.dropped
    assert c.dropped > c.delivered  # the producer really did outrun the consumer
