"""The SFNC features of the simulated camera, read through the driver.

Expected values come from the simulator's settings and the image geometry (PayloadSize = width *
height * bytes per pixel: one for Mono8, two for Mono12 and Mono16, which travel unpacked), not from
the driver. The XML itself is checked by an independent parse in tests/simulators/u3v/test_camera.py.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from wavestack.drivers import ProtocolError
from wavestack.drivers.u3v import U3VCamera
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

WIDTH, HEIGHT = 20, 12
BYTES_PER_PIXEL = {"Mono8": 1, "Mono12": 2, "Mono16": 2}
TIMEOUT_S = 5.0  # bounds a hang only


def flat(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, None]:
    return np.full((HEIGHT, WIDTH), 7, dtype=np.uint16), None


def opened(**settings: Any) -> U3VCamera:
    options: dict[str, Any] = {"serial": "SIM-SFNC", "width": WIDTH, "height": HEIGHT, "frame_rate_hz": 200.0,
                               "model": "WaveCam U3V-Sim", "manufacturer": "wavestack"}
    options.update(settings)
    device = SimulatedU3VCamera(U3VSimSettings(**options), flat)
    return U3VCamera.open(backend=SimulatedUsbBackend([device]), timeout_s=TIMEOUT_S)


@pytest.mark.parametrize("pixel_format", sorted(BYTES_PER_PIXEL))
def test_payload_size_follows_the_format(pixel_format: str) -> None:
    with opened(pixel_format=pixel_format) as camera:
        assert camera.node_map.info("PayloadSize").kind == "integer"
        assert camera.read_feature("PayloadSize") == WIDTH * HEIGHT * BYTES_PER_PIXEL[pixel_format]
        other = "Mono8" if pixel_format != "Mono8" else "Mono16"
        camera.set_pixel_format(other, timeout_s=1.0)
        assert camera.read_feature("PayloadSize") == WIDTH * HEIGHT * BYTES_PER_PIXEL[other]


def test_device_control_identity_strings() -> None:
    with opened() as camera:
        expected = {"DeviceVendorName": "wavestack", "DeviceModelName": "WaveCam U3V-Sim",
                    "DeviceSerialNumber": "SIM-SFNC", "DeviceFamilyName": camera.device_info.family,
                    "DeviceVersion": camera.device_info.device_version,
                    "DeviceManufacturerInfo": camera.device_info.manufacturer_info}
        for name, value in expected.items():
            assert camera.node_map.info(name).kind == "string", name
            assert camera.read_feature(name) == value, name
        assert camera.read_feature("DeviceUserID") == ""
        camera.set_device_user_id("interferometer-2", timeout_s=1.0)
        assert camera.read_feature("DeviceUserID") == "interferometer-2"
        with pytest.raises(ValueError, match="64"):
            camera.set_device_user_id("x" * 65, timeout_s=1.0)


def test_acquisition_mode_is_continuous_and_tl_params_lock_during_acquisition() -> None:
    with opened() as camera:
        mode = camera.node_map.info("AcquisitionMode")
        assert mode.kind == "enumeration" and camera.read_feature("AcquisitionMode") == "Continuous" 
        assert camera.read_feature("TLParamsLocked") == 0
        camera.start()
        try:
            assert camera.read_feature("TLParamsLocked") == 1  # as a GenTL consumer does before AcquisitionStart
            camera.read_frame(TIMEOUT_S)
        finally:
            camera.stop()
        assert camera.read_feature("TLParamsLocked") == 0
        camera.set_pixel_format("Mono8", timeout_s=1.0)
        assert camera.read_feature("PayloadSize") == WIDTH * HEIGHT


def test_reading_an_unknown_feature_names_it() -> None:
    with opened() as camera:
        with pytest.raises(ProtocolError, match="GainAuto"):
            camera.read_feature("GainAuto")
