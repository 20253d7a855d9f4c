"""The GigE Vision driver against the simulated camera on loopback: features, frames, faults."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from wavestack.drivers.errors import DeviceDisconnected, DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.gige import GigECamera
from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera

TIMEOUT_S = 2.0
WIDTH, HEIGHT = 96, 64


def ramp(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, int]:
    """Each pixel a function of its place and the block: a torn or mixed image cannot match."""
    rows, cols = np.indices((HEIGHT, WIDTH))
    return ((rows * WIDTH + cols + 7 * block_id) % 4096).astype(np.uint16), block_id


def expected(block_id: int) -> np.ndarray:
    return ramp(block_id, 0, 0.0)[0]


@contextmanager
def camera_on(**settings: object) -> Iterator[tuple[GigECamera, SimulatedGigECamera]]:
    options: dict[str, object] = {"width": WIDTH, "height": HEIGHT, "frame_rate_hz": 100.0}
    options.update(settings)
    with SimulatedGigECamera(GigESimSettings(**options), ramp) as sim:  # type: ignore[arg-type]
        with GigECamera.open(sim.url, timeout_s=TIMEOUT_S, packet_size=1500) as camera:
            yield camera, sim


def test_features_are_read_and_set_through_the_cameras_own_xml() -> None:
    with camera_on() as (camera, sim):
        assert (camera.width, camera.height, camera.pixel_format) == (WIDTH, HEIGHT, "Mono12")
        camera.set_exposure_us(2500.0, TIMEOUT_S)
        camera.set_pixel_format("Mono8", TIMEOUT_S)
        assert (camera.exposure_us, camera.pixel_format) == (2500.0, "Mono8")
        assert camera.read_feature("PayloadSize") == WIDTH * HEIGHT  # invalidated by PixelFormat, read afresh
        with pytest.raises(LimitError, match="ExposureTime"):
            camera.set_exposure_us(1e9, TIMEOUT_S)
        assert "gige" in camera.name.lower() and sim.settings.serial in camera.name


def test_frames_arrive_whole_in_order_and_count_up() -> None:
    with camera_on() as (camera, _):
        camera.start()
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(10)]
        camera.stop()
        for frame in frames:
            assert np.array_equal(frame.pixels, expected(frame.frame_id))
        assert [f.frame_id for f in frames] == sorted(f.frame_id for f in frames)
        counters = camera.counters()
        assert counters.acquired == counters.delivered + counters.dropped + counters.pending
        assert counters.bad_packets == 0 and counters.blocks_dropped == 0


def test_software_trigger_gives_one_frame_per_trigger() -> None:
    with camera_on() as (camera, sim):
        camera.set_trigger_mode(True, TIMEOUT_S)
        camera.start()
        try:
            with pytest.raises(DeviceTimeout):
                camera.read_frame(0.2)  # nothing without a trigger
            camera.trigger_software(TIMEOUT_S)
            frame = camera.read_frame(TIMEOUT_S)
            assert sim.truth(frame.frame_id) == frame.frame_id
        finally:
            camera.stop()


def test_one_percent_packet_loss_is_recovered_by_resends_or_counted_never_torn() -> None:
    with camera_on(frame_rate_hz=50.0) as (camera, sim):
        sim.faults.packet_loss = 0.01
        camera.start()
        frames = []
        deadline = time.monotonic() + 10
        while len(frames) < 40 and time.monotonic() < deadline:
            frames.append(camera.read_frame(TIMEOUT_S))
        camera.stop()
        assert len(frames) == 40
        for frame in frames:  # every frame delivered is whole: the ramp of its own block
            assert np.array_equal(frame.pixels, expected(frame.frame_id))
        counters = camera.counters()
        assert sim.counters["lost"] > 0 and counters.resend_requests > 0  # loss happened and was asked for
        # every block the camera sent is delivered, pending or counted dropped (the last one may be in flight)
        assert counters.acquired >= frames[-1].frame_id - frames[0].frame_id + 1
        assert counters.acquired == counters.delivered + counters.dropped + counters.pending


def test_reordered_packets_assemble() -> None:
    with camera_on() as (camera, sim):
        sim.faults.reorder = True
        camera.start()
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(5)]
        camera.stop()
        assert all(np.array_equal(f.pixels, expected(f.frame_id)) for f in frames)


def test_an_oversized_packet_is_refused_and_its_block_recovered() -> None:
    with camera_on() as (camera, sim):
        camera.start()
        camera.read_frame(TIMEOUT_S)
        sim.faults.oversized_packet = True
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(5)]
        camera.stop()
        assert camera.counters().bad_packets == 1
        assert all(np.array_equal(f.pixels, expected(f.frame_id)) for f in frames)


def test_a_silent_camera_is_a_device_error_within_its_timeout() -> None:
    with camera_on(heartbeat_timeout_ms=600) as (camera, sim):
        camera.start()
        camera.read_frame(TIMEOUT_S)
        sim.faults.silent = True
        started = time.monotonic()
        with pytest.raises(DeviceTimeout):
            camera.set_exposure_us(1500.0, 0.3)  # a control call: its own timeout
        assert time.monotonic() - started < 0.3 + 0.2
        with pytest.raises((DeviceDisconnected, DeviceTimeout)):
            while time.monotonic() - started < 3:  # the stream: the heartbeat loses the camera
                camera.read_frame(0.5)
        assert not camera.connected
        sim.faults.silent = False
        camera.reopen(TIMEOUT_S)  # answers again: control taken anew, acquisition resumed
        assert camera.read_frame(TIMEOUT_S).pixels.shape == (HEIGHT, WIDTH)


def test_an_acknowledge_with_the_wrong_id_is_discarded_and_named_if_nothing_else_comes() -> None:
    with camera_on() as (camera, sim):
        sim.faults.wrong_ack_id = 1  # one stale reply: discarded, the retry's answer is taken
        assert camera.width == WIDTH
        sim.faults.wrong_ack_id = 1000
        with pytest.raises(ProtocolError, match="other requests") as caught:
            camera.set_exposure_us(1500.0, 0.5)
        assert sim.settings.serial in str(caught.value)
        sim.faults.wrong_ack_id = 0


def test_a_second_host_cannot_take_control() -> None:
    with camera_on() as (_, sim):
        with pytest.raises(ProtocolError, match="ACCESS_DENIED"):
            GigECamera.open(sim.url, timeout_s=0.5)


def test_open_by_serial_through_discovery_and_nobody_there() -> None:
    with SimulatedGigECamera(GigESimSettings(serial="SN-DISC-7", width=WIDTH, height=HEIGHT), ramp) as sim:
        with GigECamera.open(f"gige://SN-DISC-7?via={sim.host}:{sim.port}", timeout_s=TIMEOUT_S) as camera:
            assert "SN-DISC-7" in camera.name and camera.width == WIDTH
        with pytest.raises(DeviceDisconnected, match="SN-OTHER"):
            GigECamera.open(f"gige://SN-OTHER?via={sim.host}:{sim.port}", timeout_s=0.3)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        free_port = probe.getsockname()[1]
    with pytest.raises((DeviceTimeout, DeviceDisconnected)):
        GigECamera.open(f"gige://127.0.0.1:{free_port}", timeout_s=0.3)


@pytest.mark.parametrize("url", ["gige://", "http://1.2.3.4", "gige://1.2.3.4:99999", "gige://a:b:c"])
def test_bad_urls_are_value_errors_before_any_io(url: str) -> None:
    with pytest.raises(ValueError, match="gige://|port|URL"):
        GigECamera.open(url, timeout_s=1.0)
