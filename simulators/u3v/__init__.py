"""Simulated USB3 Vision camera on a simulated USB bus that the real pyusb enumerates.

Build a camera with :class:`U3VSimSettings` and a renderer (``render(block_id, device_time_ns,
exposure_us) -> (pixels, truth)``), put it on a :class:`SimulatedUsbBackend`, and talk to it
through ``usb.core.find(backend=...)`` exactly as to hardware. The device side follows the
wavestack protocol sheet (``u3v_spec.md``: GenCP READMEM/WRITEMEM, ABRM/SBRM/SIRM, manifest and
GenICam XML, leader/payload/trailer streaming) and is written independently of the driver in
``wavestack.drivers.u3v``. Faults are injected through ``camera.faults``; ``unplug()``/``replug()``
simulate the cable.
"""

from __future__ import annotations

from wavestack.simulators.u3v.backend import SimulatedUsbBackend, usb_error
from wavestack.simulators.u3v.camera import SimulatedU3VCamera
from wavestack.simulators.u3v.descriptors import (EP_ACK_IN, EP_COMMAND_OUT, EP_STREAM_IN, SIM_PRODUCT_ID,
                                                  SIM_VENDOR_ID, U3V_CLASS, U3V_SUBCLASS, U3VDescriptorSet,
                                                  u3v_descriptors)
from wavestack.simulators.u3v.device_description import FEATURES, DeviceIdentity, FeatureSpec
from wavestack.simulators.u3v.genicam_xml import genicam_xml
from wavestack.simulators.u3v.register_map import GenCPStatus, Register, RegisterMap
from wavestack.simulators.u3v.registers import feature_register, vendor_registers
from wavestack.simulators.u3v.settings import (CorruptionKind, FrameRenderer, U3VSimCounters, U3VSimFaults,
                                               U3VSimSettings)
from wavestack.simulators.u3v.stream_device import PIXEL_FORMATS

__all__ = [
    "EP_ACK_IN", "EP_COMMAND_OUT", "EP_STREAM_IN", "FEATURES", "DeviceIdentity", "PIXEL_FORMATS", "SIM_PRODUCT_ID", "SIM_VENDOR_ID",
    "U3V_CLASS", "U3V_SUBCLASS", "CorruptionKind", "FeatureSpec", "FrameRenderer", "GenCPStatus",
    "Register", "RegisterMap", "SimulatedU3VCamera", "SimulatedUsbBackend", "U3VDescriptorSet", "U3VSimCounters",
    "U3VSimFaults", "U3VSimSettings", "feature_register", "genicam_xml", "u3v_descriptors", "usb_error",
    "vendor_registers",
]
