"""A real vendor's GigE Vision XML (Basler ace acA1920-25gm: big-endian registers, the SFNC 1.x
ExposureTimeAbs through a Converter, PixelFormat through an IntConverter onto Basler's codes),
served by the simulated GigE camera: the eight features driven and read back, frames streamed."""

from __future__ import annotations

import numpy as np
import pytest

from shared_data import require_shared_data
from vendor_cameras import SETTINGS, VENDOR_XML
from wavestack.drivers.errors import LimitError
from wavestack.drivers.gige import GigECamera
from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera

pytestmark = require_shared_data()
TIMEOUT_S = 2.0


def flat(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, float]:
    return np.full((48, 64), block_id % 200, dtype=np.uint16), exposure_us


def test_basler_ace_features_are_driven_and_read_back() -> None:
    vendor = "basler-ace-gige"
    pixel_format, exposure_us = SETTINGS[vendor]
    settings = GigESimSettings(serial="SIM-BASLER", width=64, height=48, pixel_format="Mono12", frame_rate_hz=100.0,
                               vendor=vendor, vendor_xml=str(VENDOR_XML[vendor]))
    with SimulatedGigECamera(settings, flat) as sim, GigECamera.open(sim.url, timeout_s=TIMEOUT_S) as camera:
        node_map = camera.node_map
        for feature in ("Width", "Height", "PixelFormat", "ExposureTimeAbs", "TriggerMode", "TriggerSoftware",
                        "AcquisitionStart", "AcquisitionStop"):
            assert feature in node_map, feature
        assert "ExposureTime" not in node_map  # SFNC 1.x naming: the driver asks for ExposureTimeAbs
        assert (camera.width, camera.height, camera.pixel_format) == (64, 48, "Mono12")
        camera.write_feature("Width", 128, TIMEOUT_S)
        camera.write_feature("Height", 32, TIMEOUT_S)
        camera.set_pixel_format(pixel_format, TIMEOUT_S)
        camera.set_exposure_us(exposure_us, TIMEOUT_S)  # 123 counts of the camera's 20 µs time base
        assert (camera.width, camera.height, camera.pixel_format, camera.exposure_us) == (
            128, 32, pixel_format, exposure_us)
        with pytest.raises(LimitError, match="Width"):
            camera.write_feature("Width", 130, TIMEOUT_S)  # Inc 8
        camera.write_feature("Width", 64, TIMEOUT_S)
        camera.write_feature("Height", 48, TIMEOUT_S)
        camera.set_trigger_mode(True, TIMEOUT_S)
        assert camera.read_feature("TriggerMode") == "On"
        camera.start()
        try:
            camera.trigger_software(TIMEOUT_S)
            frame = camera.read_frame(TIMEOUT_S)
        finally:
            camera.stop()
        assert frame.pixels.shape == (48, 64) and frame.metadata["pixel_format"] == pixel_format
        assert sim.truth(frame.frame_id) == pytest.approx(exposure_us)
        camera.set_trigger_mode(False, TIMEOUT_S)
        assert camera.read_feature("TriggerMode") == "Off"
