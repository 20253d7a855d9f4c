"""U3VCamera against the simulated camera, through the real pyusb API (usb.core.find + a simulated backend).

Fault injection goes through the simulator's own ``faults`` switches. Expected pixels come from the
simulator's ground truth (the renderer returns the pixels it drew as the truth).
"""

from __future__ import annotations

import gc
import threading
import time
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

from wavestack.drivers import (DeviceDisconnected, DeviceTimeout, Frame, FrameSource, LimitError, ProtocolError,
                               RingPolicy)
from wavestack.drivers.u3v import U3VCamera
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

WIDTH, HEIGHT = 64, 48
FORMAT_MAX = {"Mono8": 255, "Mono12": 4095, "Mono16": 65535}
TIMEOUT_S = 5.0  # generous: only bounds a hang, never asserts a speed


class Pattern:
    """Renderer: seeded random counts in 0..max_value per block id; the truth is the pixels themselves."""

    def __init__(self, max_value: int, width: int = WIDTH, height: int = HEIGHT) -> None:
        self.max_value, self.width, self.height = max_value, width, height

    def __call__(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, np.ndarray]:
        rng = np.random.default_rng(block_id)
        pixels = rng.integers(0, self.max_value + 1, size=(self.height, self.width), dtype=np.uint16)
        return pixels, pixels.copy()


def sim(serial: str = "SIM-A", max_value: int = 4095, **settings: Any) -> SimulatedU3VCamera:
    options: dict[str, Any] = {"width": WIDTH, "height": HEIGHT, "pixel_format": "Mono12", "frame_rate_hz": 100.0}
    options.update(settings)
    return SimulatedU3VCamera(U3VSimSettings(serial=serial, **options),
                              Pattern(max_value, options["width"], options["height"]))


@contextmanager
def opened(device: SimulatedU3VCamera, **kwargs: Any) -> Iterator[U3VCamera]:
    with U3VCamera.open(backend=SimulatedUsbBackend([device]), timeout_s=TIMEOUT_S, **kwargs) as camera:
        yield camera


def assert_matches_truth(frame: Frame, device: SimulatedU3VCamera, pixel_format: str) -> None:
    truth = device.truth(frame.frame_id)
    expected = np.minimum(truth, FORMAT_MAX[pixel_format])  # the sensor saturates at the format's maximum
    assert frame.pixels.dtype == (np.uint8 if pixel_format == "Mono8" else np.uint16)
    assert frame.pixels.shape == truth.shape
    np.testing.assert_array_equal(frame.pixels, expected)
    assert frame.metadata["pixel_format"] == pixel_format


def drain(camera: U3VCamera) -> list[Frame]:
    """Frames still pending after stop()."""
    frames = []
    while True:
        try:
            frames.append(camera.read_frame(0.05))
        except DeviceTimeout:
            return frames


def read_past_fault(camera: U3VCamera, fault_seen: Any) -> list[Frame]:
    """Frames until the reader thread has met a one-shot fault, then one more frame taken after it.

    A frame ring may hold frames acquired before the fault switch was set (a loaded machine lets
    the reader run ahead of the test), so a fixed number of reads may never reach the fault.
    """
    frames: list[Frame] = []
    deadline = time.monotonic() + TIMEOUT_S
    while not fault_seen(camera.counters()):
        assert time.monotonic() < deadline, f"the fault was not met within {TIMEOUT_S} s"
        frames.append(camera.read_frame(TIMEOUT_S))
    frames.append(camera.read_frame(TIMEOUT_S))
    return frames


def reader_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("u3v-reader") and t.is_alive()]


# ------------------------------------------------------------------------------ open, features
def test_open_by_class_and_by_serial() -> None:
    first, second = sim("SIM-A"), sim("SIM-B", zipped_xml=True)  # the second serves its XML zipped
    backend = SimulatedUsbBackend([first, second])
    with U3VCamera.open(backend=backend, timeout_s=TIMEOUT_S) as camera:
        assert camera.device_info.serial_number == "SIM-A"
        assert isinstance(camera, FrameSource)
    with U3VCamera.open(backend=backend, serial="SIM-B", timeout_s=TIMEOUT_S) as camera:
        assert camera.device_info.serial_number == "SIM-B" and "SIM-B" in camera.name
        assert (camera.width, camera.height, camera.pixel_format) == (WIDTH, HEIGHT, "Mono12")
    with pytest.raises(DeviceDisconnected, match="SIM-C"):
        U3VCamera.open(backend=backend, serial="SIM-C", timeout_s=TIMEOUT_S)


def test_features_round_trip_and_validation() -> None:
    device = sim(exposure_us=1000.0)
    with opened(device) as camera:
        assert camera.exposure_us == 1000.0
        camera.set_exposure_us(2500.25, timeout_s=TIMEOUT_S)
        assert camera.exposure_us == 2500.25  # a float64 register round-trips exactly
        camera.set_pixel_format("Mono16", timeout_s=TIMEOUT_S)
        assert camera.pixel_format == "Mono16"
        commands = device.counters.commands_received
        with pytest.raises(LimitError):
            camera.set_exposure_us(0.5, timeout_s=TIMEOUT_S)  # below the XML's Min of 1 us
        with pytest.raises(ValueError):
            camera.set_exposure_us(float("nan"), timeout_s=TIMEOUT_S)
        with pytest.raises(ValueError):
            camera.set_pixel_format("Mono10", timeout_s=TIMEOUT_S)
        assert device.counters.commands_received == commands  # refused before any I/O


def test_device_error_status_names_feature_and_status() -> None:
    with opened(sim()) as camera:  # free-run: the simulator refuses TriggerSoftware with ACCESS_DENIED
        with pytest.raises(ProtocolError, match="TriggerSoftware.*ACCESS_DENIED"):
            camera.trigger_software(timeout_s=TIMEOUT_S)
        assert camera.width == WIDTH  # the control channel is still in step afterwards


# ------------------------------------------------------------------------------------ frames
@pytest.mark.parametrize("pixel_format", ["Mono8", "Mono12", "Mono16"])
def test_frames_equal_rendered_pixels(pixel_format: str) -> None:
    device = sim(max_value=FORMAT_MAX[pixel_format], pixel_format="Mono16" if pixel_format != "Mono16" else "Mono8")
    with opened(device, ring_policy=RingPolicy.OLDEST_FIRST, ring_capacity=8) as camera:
        camera.set_pixel_format(pixel_format, timeout_s=TIMEOUT_S)
        camera.start()
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(4)]
        camera.stop()
    for frame in frames:
        assert_matches_truth(frame, device, pixel_format)
    if pixel_format != "Mono8":  # the high byte is carried: uniform counts up to 4095 reach far above 255
        assert max(int(f.pixels.max()) for f in frames) > 255
    assert [f.frame_id for f in frames] == sorted({f.frame_id for f in frames})


def test_software_trigger() -> None:
    device = sim(frame_rate_hz=1000.0)
    with opened(device, ring_policy=RingPolicy.OLDEST_FIRST) as camera:
        camera.set_trigger_mode(True, timeout_s=TIMEOUT_S)
        camera.start()
        with pytest.raises(DeviceTimeout):
            camera.read_frame(0.3)  # no trigger, no frame; the reader keeps waiting through USB timeouts
        camera.trigger_software(timeout_s=TIMEOUT_S)
        first = camera.read_frame(TIMEOUT_S)
        camera.trigger_software(timeout_s=TIMEOUT_S)
        camera.trigger_software(timeout_s=TIMEOUT_S)
        later = [camera.read_frame(TIMEOUT_S) for _ in range(2)]
        camera.stop()
        counters = camera.counters()
    assert [first.frame_id] + [f.frame_id for f in later] == [0, 1, 2]  # one block per trigger
    for frame in [first, *later]:
        assert_matches_truth(frame, device, "Mono12")
    assert (counters.acquired, counters.delivered, counters.dropped) == (3, 3, 0)
    assert counters.stream_timeouts >= 1


def test_read_frame_times_out_when_not_started() -> None:
    with opened(sim()) as camera:
        with pytest.raises(DeviceTimeout):
            camera.read_frame(0.05)


def _has_gap(frames: list[Frame]) -> bool:
    return any(b.frame_id - a.frame_id > 1 for a, b in zip(frames, frames[1:]))


def test_free_run_gaps_counted_as_drops() -> None:
    device = sim(frame_rate_hz=200.0)
    with opened(device, ring_policy=RingPolicy.OLDEST_FIRST, ring_capacity=256) as camera:
        camera.start()
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(3)]
        # three stream reads that each wait out their 100 ms timeout: the free-running camera moves on.
        # Frames buffered in the ring before the stall come first, so read until the first frame after
        # it arrives (a gap in the ids), whatever the machine's load; the deadline only bounds a hang.
        device.faults.timeout_reads = 3
        deadline = time.monotonic() + 4 * TIMEOUT_S
        while not _has_gap(frames) and time.monotonic() < deadline:
            frames.append(camera.read_frame(TIMEOUT_S))
        frames += [camera.read_frame(TIMEOUT_S) for _ in range(2)]
        camera.stop()
        frames += drain(camera)
        counters = camera.counters()
    ids = [f.frame_id for f in frames]
    gaps = sum(b - a - 1 for a, b in zip(ids, ids[1:]))
    assert ids == sorted(set(ids))
    assert gaps > 0  # 300 ms without stream reads at 200 frames/s
    assert counters.dropped_in_gaps == gaps and counters.dropped == gaps  # the ring never filled (256 slots)
    assert counters.acquired == ids[-1] - ids[0] + 1 == counters.delivered + counters.dropped
    assert counters.pending == 0 and counters.stream_timeouts >= 3
    assert device.counters.frames_skipped >= gaps  # the camera's own count of frames it overwrote
    for frame in frames[-3:]:
        assert_matches_truth(frame, device, "Mono12")


@pytest.mark.parametrize("policy", [RingPolicy.NEWEST_ONLY, RingPolicy.OLDEST_FIRST])
def test_ring_overrun_keeps_counters_exact(policy: RingPolicy) -> None:
    capacity = 3
    device = sim(frame_rate_hz=400.0, width=32, height=24, pixel_format="Mono8", max_value=255)
    with opened(device, ring_policy=policy, ring_capacity=capacity) as camera:
        camera.start()
        ids = []
        end = time.monotonic() + 1.0  # a consumer ~10x slower than the camera, for one second per policy
        while time.monotonic() < end:
            ids.append(camera.read_frame(TIMEOUT_S).frame_id)
            counters = camera.counters()
            assert counters.pending <= capacity
            assert counters.acquired == counters.delivered + counters.dropped + counters.pending
            time.sleep(0.025)
        camera.stop()
        ids += [f.frame_id for f in drain(camera)]
        final = camera.counters()
    assert ids == sorted(set(ids))
    assert final.pending == 0 and final.acquired == final.delivered + final.dropped
    assert final.delivered == len(ids)
    assert final.dropped > 0  # 400 frames/s offered, fewer than 40/s taken


# ------------------------------------------------------------------------------------ faults
@pytest.mark.parametrize("fault,value", [
    ("partial_transfer", True),
    ("corrupt_leader", "magic"), ("corrupt_leader", "block_id"), ("corrupt_leader", "size"),
    ("corrupt_trailer", "magic"), ("corrupt_trailer", "block_id"), ("corrupt_trailer", "size"),
])
def test_bad_block_is_discarded_and_the_next_is_good(fault: str, value: object) -> None:
    device = sim()
    with opened(device, ring_policy=RingPolicy.OLDEST_FIRST, ring_capacity=64) as camera:
        camera.start()
        frames = [camera.read_frame(TIMEOUT_S)]
        setattr(device.faults, fault, value)
        frames += read_past_fault(camera, lambda counters: counters.discarded_blocks > 0)
        camera.stop()
        frames += drain(camera)
        counters = camera.counters()
    assert counters.discarded_blocks == 1  # exactly the damaged block
    assert counters.dropped_in_gaps >= 1  # ... which shows up as a gap in the block ids
    assert counters.acquired == counters.delivered + counters.dropped
    assert counters.transfer_errors == 0
    for frame in frames:  # nothing damaged was delivered
        assert_matches_truth(frame, device, "Mono12")


def test_stall_is_cleared_and_streaming_resumes() -> None:
    device = sim()
    with opened(device, ring_policy=RingPolicy.OLDEST_FIRST, ring_capacity=64) as camera:
        camera.start()
        frames = [camera.read_frame(TIMEOUT_S)]
        device.faults.stall_next = True
        frames += read_past_fault(camera, lambda counters: counters.stalls_cleared > 0)
        camera.stop()
        counters = camera.counters()
    assert counters.stalls_cleared == 1
    assert counters.acquired == counters.delivered + counters.dropped + counters.pending
    for frame in frames:
        assert_matches_truth(frame, device, "Mono12")


def test_pending_ack_extends_the_response_time() -> None:
    device = sim(max_response_time_ms=100)
    with opened(device) as camera:
        # the real acknowledge comes half the advertised 400 ms later: after the 100 ms response time
        device.faults.pending_ack_ms = 400
        camera.set_exposure_us(1234.0, timeout_s=TIMEOUT_S)
        assert camera.exposure_us == 1234.0
        # a device that needs longer than the caller allows: the call's own timeout wins
        device.faults.pending_ack_ms = 1200
        with pytest.raises(DeviceTimeout):
            camera.set_exposure_us(2000.0, timeout_s=0.3)
        device.faults.pending_ack_ms = 0
        # the late acknowledge of the abandoned request is discarded by its request id
        camera.set_exposure_us(3000.0, timeout_s=TIMEOUT_S)
        assert camera.exposure_us == 3000.0


def test_control_from_two_threads_while_streaming() -> None:
    device = sim()
    errors: list[BaseException] = []
    with opened(device, ring_policy=RingPolicy.OLDEST_FIRST, ring_capacity=64) as camera:
        camera.start()
        # every acknowledge comes 10 ms late (after a PENDING_ACK), so both threads' commands are in
        # flight together unless the control channel serialises them
        device.faults.pending_ack_ms = 20

        def hammer(offset: float) -> None:
            try:
                for index in range(10):
                    camera.set_exposure_us(100.0 + offset + index, timeout_s=TIMEOUT_S)
                    assert camera.width == WIDTH
            except BaseException as exc:  # reported to the test thread
                errors.append(exc)

        workers = [threading.Thread(target=hammer, args=(offset,)) for offset in (0.0, 1000.0)]
        for worker in workers:
            worker.start()
        for _ in range(3):  # checked at once: the simulator keeps the truth of the last 64 blocks only
            assert_matches_truth(camera.read_frame(TIMEOUT_S), device, "Mono12")
        for worker in workers:
            worker.join()
        camera.stop()
    assert errors == []


# ------------------------------------------------------------------------------ unplug, replug
def wait_for_disconnect(camera: U3VCamera) -> DeviceDisconnected:
    for _ in range(64):  # pending frames come first, then the error
        try:
            camera.read_frame(TIMEOUT_S)
        except DeviceDisconnected as exc:
            return exc
    raise AssertionError("no DeviceDisconnected after the unplug")


def wait_for_no_reader() -> list[threading.Thread]:
    deadline = time.monotonic() + TIMEOUT_S
    while reader_threads() and time.monotonic() < deadline:
        time.sleep(0.01)
    return reader_threads()


def wait_until_not_reading(camera: U3VCamera) -> bool:
    deadline = time.monotonic() + TIMEOUT_S
    while camera.reading and time.monotonic() < deadline:
        time.sleep(0.01)
    return not camera.reading


def test_unplug_mid_stream() -> None:
    device = sim()
    with opened(device) as camera:
        camera.start()
        camera.read_frame(TIMEOUT_S)
        device.unplug()
        error = wait_for_disconnect(camera)
        with pytest.raises(DeviceDisconnected) as again:
            camera.read_frame(0.1)
        # the ring was closed once, with one error (raised as a new object each time: drivers.errors.renewed)
        assert (type(again.value), str(again.value)) == (type(error), str(error)) and again.value is not error
        assert wait_until_not_reading(camera)  # the reader ended by itself (its thread waits for the next start)
        with pytest.raises(DeviceDisconnected):
            camera.set_exposure_us(500.0, timeout_s=TIMEOUT_S)
        with pytest.raises(DeviceDisconnected):
            _ = camera.width
        camera.stop()  # tolerated after an unplug


class _CallersState:
    """Something a caller of the camera holds in a local (a phase-step source, its ring of sets)."""


def test_a_disconnect_seen_by_a_command_keeps_nothing_of_its_caller() -> None:
    """The camera keeps why it was lost (raised again by every later call), but not the raised
    error itself: its traceback reaches the caller's frame, and with it the caller's locals, for as
    long as the camera lives."""
    device = sim()
    with opened(device) as camera:
        held: list[weakref.ref] = []

        def caller() -> None:
            state = _CallersState()
            held.append(weakref.ref(state))
            camera.set_exposure_us(500.0, timeout_s=TIMEOUT_S)  # the control channel sees the unplug

        device.unplug()
        gc.disable()  # only reference counting frees: what the camera keeps stays
        try:
            with pytest.raises(DeviceDisconnected, match="device is gone"):
                caller()
            assert held[0]() is None, "the camera keeps the caller's frame through the error it raised"
        finally:
            gc.enable()
        with pytest.raises(DeviceDisconnected, match="unplugged"):
            camera.set_exposure_us(500.0, timeout_s=TIMEOUT_S)  # the loss is still known


def test_replug_and_reopen_streams_again() -> None:
    device = sim()
    with opened(device) as camera:
        camera.start()
        camera.read_frame(TIMEOUT_S)
        device.unplug()
        wait_for_disconnect(camera)
        with pytest.raises(DeviceDisconnected):
            camera.reopen(timeout_s=0.2)  # still unplugged
        device.replug()
        readers = reader_threads()
        camera.reopen(timeout_s=TIMEOUT_S)  # acquisition was running: it resumes
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(3)]
        # on the same reader thread: a new thread per acquisition gets a new malloc arena (drivers.role_thread)
        assert len(readers) == 1 and reader_threads() == readers
        camera.stop()
    for frame in frames:
        assert_matches_truth(frame, device, "Mono12")
    assert wait_for_no_reader() == []


def test_close_is_idempotent_and_final() -> None:
    camera = U3VCamera.open(backend=SimulatedUsbBackend([sim()]), timeout_s=TIMEOUT_S)
    camera.start()
    camera.close()
    camera.close()
    assert reader_threads() == []
    with pytest.raises(DeviceDisconnected):
        camera.read_frame(0.05)
    with pytest.raises(DeviceDisconnected):
        camera.start()


def test_frames_pending_at_close_are_not_delivered() -> None:
    """Closing is final: a frame the reader had put in the ring before the close is not read after it."""
    camera = U3VCamera.open(backend=SimulatedUsbBackend([sim()]), timeout_s=TIMEOUT_S)
    camera.start()
    deadline = time.monotonic() + TIMEOUT_S
    while camera.counters().pending == 0:
        assert time.monotonic() < deadline, "no frame reached the ring"
        time.sleep(0.005)
    camera.close()
    with pytest.raises(DeviceDisconnected):
        camera.read_frame(0.05)
