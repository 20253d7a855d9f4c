"""Simulated instruments: each device seen from the other end of the wire.

A simulator re-implements the device side from the protocol description and never imports the
driver's parser. Families: :mod:`~wavestack.simulators.u3v` (a pyusb backend serving a USB3
Vision camera), :mod:`~wavestack.simulators.mdt693b` (the piezo controller behind ``sim://`` or a
pseudo-terminal), :mod:`~wavestack.simulators.plc` (a pymodbus server with a watchdog and a
polishing model). :mod:`~wavestack.simulators.optic` and :mod:`~wavestack.simulators.spots` render
what the cameras see, :mod:`~wavestack.simulators.bench` wires camera, piezo and optic together.
:class:`SurfaceState` is the optic's height map (built from :class:`SurfaceSettings`), which the
simulated polishing machine changes.

The ``sim://`` URL handler for pyserial is registered only by an explicit call to
:func:`register_serial_simulators`.
"""

from __future__ import annotations

from wavestack.simulators.serial_registry import attach_simulated_device, register_serial_simulators
from wavestack.simulators.surface import SurfaceSnapshot, SurfaceState
from wavestack.simulators.surface_settings import SurfaceSettings

__all__ = ["SurfaceSettings", "SurfaceSnapshot", "SurfaceState", "attach_simulated_device",
           "register_serial_simulators"]
