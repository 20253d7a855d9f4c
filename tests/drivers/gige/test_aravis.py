"""Against an independent GigE Vision and GenICam implementation: Debian's aravis.

``arv-tool`` (aravis' own GVCP client and GenApi evaluator) discovers our simulated camera, lists
its features, reads and writes them and its bootstrap registers; our driver streams from
``arv-fake-gv-camera`` (aravis' device side). ``python3 ws.py test`` installs both programs.

Both bind GVCP's own port 3956, which a client such as arv-tool cannot be told otherwise: our
simulator on a loopback address of its own (127.0.0.0/8 all reaches this machine), the fake camera
on 127.0.0.1 (the one loopback address it accepts). The tests of this file run one after another.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import time
from collections.abc import Iterator

import numpy as np
import pytest

from wavestack.drivers.gige import GigECamera
from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera

ARV_TOOL, FAKE_CAMERA = "arv-tool-0.8", "arv-fake-gv-camera-0.8"


def _free_loopback_for_gvcp() -> str:
    """A loopback address whose UDP port 3956 is free."""
    for last in range(71, 120):
        address = f"127.0.0.{last}"
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind((address, 3956))
            except OSError:
                continue
        return address
    raise AssertionError("no loopback address with UDP port 3956 free")


def _arv_tool(address: str, *args: str) -> str:
    assert shutil.which(ARV_TOOL), f"{ARV_TOOL} is missing: `python3 ws.py test` installs Debian's aravis-tools-cli"
    done = subprocess.run([ARV_TOOL, "-a", address, *args], capture_output=True, text=True, timeout=30, check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout


def ramp(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, int]:
    return np.full((48, 64), block_id, dtype=np.uint16), block_id


@pytest.fixture
def simulated_camera() -> Iterator[SimulatedGigECamera]:
    settings = GigESimSettings(serial="WS-ARV-1", width=64, height=48, host=_free_loopback_for_gvcp(), port=3956)
    with SimulatedGigECamera(settings, ramp) as camera:
        yield camera


def test_arv_tool_finds_reads_and_writes_the_simulated_camera(simulated_camera: SimulatedGigECamera) -> None:
    address = simulated_camera.host
    assert address in _arv_tool(address)  # DISCOVERY answered
    listed = _arv_tool(address, "features")
    for feature in ("Width", "Height", "PixelFormat", "ExposureTime", "TriggerMode", "TriggerSoftware",
                    "AcquisitionStart", "AcquisitionStop"):
        assert f"'{feature}'" in listed, feature
    values = _arv_tool(address, "control", "Width", "PixelFormat", "ExposureTime", "R[0x0000]", "R[0x0904]")
    assert "Width = 64" in values and "PixelFormat = Mono12" in values and "ExposureTime = 1000" in values
    assert "R[0x00000000] = 0x00020000" in values and "R[0x00000904] = 0x00000001" in values  # GigE Vision 2.0, 1 channel
    _arv_tool(address, "control", "Width=32", "ExposureTime=2500")
    after = _arv_tool(address, "control", "Width", "ExposureTime")
    assert "Width = 32" in after and "ExposureTime = 2500" in after
    assert simulated_camera.get_feature("Width") == 32  # the device took it


def test_the_driver_streams_from_aravis_fake_camera() -> None:
    assert shutil.which(FAKE_CAMERA), f"{FAKE_CAMERA} is missing: `python3 ws.py test` installs Debian's aravis-tools"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 3956))  # fails the test (not skips) if something else holds the port
    fake = subprocess.Popen([FAKE_CAMERA, "-i", "127.0.0.1", "-s", "WSFAKE"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                camera = GigECamera.open("gige://127.0.0.1", timeout_s=1.0, packet_size=1500)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        with camera:
            assert "WSFAKE" in camera.name and camera.pixel_format == "Mono8"
            camera.write_feature("Width", 256, 1.0)
            camera.write_feature("Height", 128, 1.0)
            initial = camera.exposure_us
            camera.set_exposure_us(20_000.0, 1.0)  # aravis names it ExposureTimeAbs (SFNC 1.x)
            assert camera.exposure_us == 20_000.0
            camera.set_exposure_us(initial, 1.0)  # its pattern's brightness follows the exposure: back to 1:1
            camera.start()
            frames = [camera.read_frame(5.0) for _ in range(3)]
            camera.stop()
        for frame in frames:  # aravis' test pattern: a diagonal ramp, each pixel one grey level above its left and upper neighbours
            pixels = frame.pixels.astype(np.int64)
            assert pixels.shape == (128, 256) and pixels.dtype == np.int64
            rows, cols = np.indices(pixels.shape)
            assert np.array_equal((pixels - pixels[0, 0]) % 255, (rows + cols) % 255)  # values cycle 0..254
        assert [f.frame_id for f in frames] == list(range(frames[0].frame_id, frames[0].frame_id + 3))
    finally:
        fake.terminate()
        fake.wait(10)
