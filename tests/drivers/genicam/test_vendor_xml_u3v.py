"""Real vendors' USB3 Vision XML (FLIR Blackfly S, Allied Vision Alvium), served by the simulated
camera behind their register maps: the driver opens each, drives the station's eight features
through the real node types, streams, and reads back what it set."""

from __future__ import annotations

import numpy as np
import pytest

from shared_data import require_shared_data
from vendor_cameras import SETTINGS, VENDOR_XML
from wavestack.drivers.errors import LimitError, ProtocolError
from wavestack.drivers.u3v import U3VCamera
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

pytestmark = require_shared_data()
TIMEOUT_S = 2.0


def flat(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, float]:
    return np.full((48, 64), block_id % 200, dtype=np.uint16), exposure_us


def open_vendor(vendor: str) -> tuple[U3VCamera, SimulatedU3VCamera]:
    device = SimulatedU3VCamera(U3VSimSettings(serial=f"SIM-{vendor}", width=64, height=48, pixel_format="Mono8",
                                               frame_rate_hz=200.0, vendor=vendor,
                                               vendor_xml=str(VENDOR_XML[vendor])), flat)
    return U3VCamera.open(backend=SimulatedUsbBackend([device]), timeout_s=TIMEOUT_S), device


@pytest.mark.parametrize("vendor", ["flir-bfs", "alvium-1800u"])
def test_the_eight_features_are_driven_and_read_back(vendor: str) -> None:
    camera, device = open_vendor(vendor)
    pixel_format, exposure_us = SETTINGS[vendor]
    with camera:
        for feature in ("Width", "Height", "PixelFormat", "ExposureTime", "TriggerMode", "TriggerSoftware",
                        "AcquisitionStart", "AcquisitionStop"):
            assert feature in camera.node_map, feature
        assert (camera.width, camera.height, camera.pixel_format) == (64, 48, "Mono8")
        camera.write_feature("Width", 96, TIMEOUT_S)
        camera.write_feature("Height", 32, TIMEOUT_S)
        camera.set_pixel_format(pixel_format, TIMEOUT_S)
        camera.set_exposure_us(exposure_us, TIMEOUT_S)
        assert (camera.width, camera.height, camera.pixel_format, camera.exposure_us) == (
            96, 32, pixel_format, exposure_us)
        camera.write_feature("Width", 64, TIMEOUT_S)
        camera.write_feature("Height", 48, TIMEOUT_S)
        camera.set_trigger_mode(True, TIMEOUT_S)
        assert camera.read_feature("TriggerMode") == "On"
        camera.start()
        try:
            mark = camera.loss_mark()
            camera.trigger_software(TIMEOUT_S)
            frame = camera.read_frame(TIMEOUT_S, since_loss=mark)
        finally:
            camera.stop()
        assert frame.pixels.shape == (48, 64) and frame.metadata["pixel_format"] == pixel_format
        assert device.truth(frame.frame_id) == pytest.approx(exposure_us)  # the device exposed what was set
        camera.set_trigger_mode(False, TIMEOUT_S)
        assert camera.read_feature("TriggerMode") == "Off"


@pytest.mark.parametrize("vendor", ["flir-bfs", "alvium-1800u"])
def test_values_outside_the_xml_limits_are_refused_before_the_wire(vendor: str) -> None:
    camera, device = open_vendor(vendor)
    with camera:
        before = device.counters.commands_received
        with pytest.raises(LimitError, match="Width"):
            camera.write_feature("Width", 16385, TIMEOUT_S)
        with pytest.raises(LimitError, match="ExposureTime"):
            camera.set_exposure_us(1e9, TIMEOUT_S)
        with pytest.raises(LimitError, match="PixelFormat"):
            camera.write_feature("PixelFormat", "BayerRG8", TIMEOUT_S)
        assert camera.width == 64
        assert device.counters.commands_received - before >= 1  # limits are read from the device...


def test_tl_params_lock_makes_the_size_read_only_during_acquisition() -> None:
    camera, _ = open_vendor("alvium-1800u")  # Alvium locks Width/PixelFormat/TriggerMode while TLParamsLocked = 1
    with camera:
        camera.start()
        try:
            assert camera.node_map.access("Width") == "RO"
            with pytest.raises(ProtocolError, match="Width.*not writable"):
                camera.write_feature("Width", 96, TIMEOUT_S)
        finally:
            camera.stop()
        assert camera.node_map.access("Width") == "RW"
