"""The driver reaches a simulated camera served over TCP (``usbtcp://``) exactly as over a local bus.

The camera simulator's own backend is served by :class:`~wavestack.simulators.usb_tcp.UsbTcpServer`;
the driver opens it through :class:`~wavestack.drivers.usb_tcp.UsbTcpBackend`. Expected pixel
values come from the simulator's frame source, not from the driver.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.drivers import DeviceError
from wavestack.drivers.u3v import U3VCamera
from wavestack.drivers.usb_tcp import UsbTcpBackend, parse_usbtcp_url
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings
from wavestack.simulators.usb_tcp import UsbTcpServer

WIDTH, HEIGHT = 24, 10
TIMEOUT_S = 5.0  # bounds a hang only


def ramp(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, None]:
    return (np.arange(HEIGHT * WIDTH, dtype=np.uint16).reshape(HEIGHT, WIDTH) + block_id) % 4096, None


def _device() -> SimulatedU3VCamera:
    return SimulatedU3VCamera(U3VSimSettings(serial="SIM-TCP", width=WIDTH, height=HEIGHT, frame_rate_hz=200.0,
                                             pixel_format="Mono12"), ramp)


def test_frames_arrive_through_the_tunnel() -> None:
    device = _device()
    with UsbTcpServer(SimulatedUsbBackend([device])) as server:
        backend = UsbTcpBackend("127.0.0.1", server.port)
        with U3VCamera.open(backend=backend, serial="SIM-TCP", timeout_s=TIMEOUT_S) as camera:
            assert camera.read_feature("Width") == WIDTH
            camera.start()
            frame = camera.read_frame(timeout_s=TIMEOUT_S)
            expected, _ = ramp(frame.frame_id, 0, 0.0)
            assert np.array_equal(np.asarray(frame.pixels), expected)
            camera.stop()
        backend.close()


def test_a_dropped_connection_is_a_lost_camera_and_it_comes_back() -> None:
    device = _device()
    with UsbTcpServer(SimulatedUsbBackend([device])) as server:
        backend = UsbTcpBackend("127.0.0.1", server.port)
        with U3VCamera.open(backend=backend, timeout_s=TIMEOUT_S) as camera:
            camera.start()
            camera.read_frame(timeout_s=TIMEOUT_S)
            server.disconnect_clients()
            with pytest.raises(DeviceError):
                for _ in range(50):
                    camera.read_frame(timeout_s=0.5)
            assert camera.present()
            camera.reopen(timeout_s=TIMEOUT_S)
            camera.read_frame(timeout_s=TIMEOUT_S)
            camera.stop()
        backend.close()


def test_no_server_no_camera() -> None:
    with pytest.raises(DeviceError):
        U3VCamera.open(backend=UsbTcpBackend("127.0.0.1", 1), timeout_s=0.5)


def test_url() -> None:
    assert parse_usbtcp_url("usbtcp://localhost:7000") == ("localhost", 7000, None)
    with pytest.raises(ValueError, match="usbtcp://HOST:PORT"):
        parse_usbtcp_url("usb://x")
