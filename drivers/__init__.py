"""Device drivers: bytes and devices, nothing about Zernike terms.

Common ground lives here (frames, the frame ring, typed errors, the safety stage every actuator
output passes); each device family has its own package with a pure ``protocol`` side and an I/O
side: :mod:`~wavestack.drivers.genicam` (the GenICam node map of any camera, :class:`NodeMap`),
:mod:`~wavestack.drivers.u3v` (USB3 Vision cameras over pyusb), :mod:`~wavestack.drivers.gige`
(GigE Vision cameras over UDP),
:mod:`~wavestack.drivers.mdt693b` (Thorlabs piezo controllers over pyserial),
:mod:`~wavestack.drivers.plc` (the polishing-station PLC over Modbus/TCP) and
:mod:`~wavestack.drivers.pi_gcs` (PI hexapods and stages, GCS 2.0 over TCP or RS-232). The family
packages are imported explicitly, so importing this one loads no USB, serial or Modbus library.
"""

from __future__ import annotations

from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.frames import Frame, FrameSource, SlopeFrame, SlopeSource
from wavestack.drivers.genicam import NodeMap
from wavestack.drivers.ring import FrameRing, RingCounters, RingPolicy
from wavestack.drivers.safety import SafeOutput, SafetyLimits, SafetyStage, SafetyStatus

__all__ = [
    "DeviceDisconnected", "DeviceError", "DeviceTimeout", "LimitError", "ProtocolError",
    "Frame", "FrameSource", "SlopeFrame", "SlopeSource", "NodeMap",
    "FrameRing", "RingCounters", "RingPolicy",
    "SafeOutput", "SafetyLimits", "SafetyStage", "SafetyStatus",
]
