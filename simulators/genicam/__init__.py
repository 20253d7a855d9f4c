"""The device side of GenICam: vendor register maps a simulated camera serves behind a real XML.

:data:`PERSONALITIES` holds three real cameras' maps (FLIR Blackfly S, Allied Vision Alvium, Basler
ace); :func:`personality_registers` turns one into the registers of a simulated USB3 Vision or
GigE Vision camera, and :func:`read_vendor_xml` reads the XML file as the camera serves it.
"""

from __future__ import annotations

from wavestack.simulators.genicam.personality import (PFNC, CameraHooks, RegisterSpec, VendorPersonality,
                                                      read_vendor_xml, register_accessors)
from wavestack.simulators.genicam.vendors import PERSONALITIES

__all__ = ["PERSONALITIES", "PFNC", "CameraHooks", "RegisterSpec", "VendorPersonality", "read_vendor_xml",
           "register_accessors"]
