"""Simulated Thorlabs MDT693B / MDT694B piezo controller.

``device`` is the controller's state machine (bytes in, bytes out), ``compatibility`` its MDT693A
command set, ``personality`` what tells one controller from another and its fault switches; ``pty_bridge``
serves it on a pseudo-terminal. The ``sim://mdt693b`` serial URL (``simulators/protocol_sim.py``,
enabled by ``register_serial_simulators()``) serves it to ``serial.serial_for_url`` without a thread.
"""

from __future__ import annotations

from wavestack.simulators.mdt693b.device import MDT693BDevice
from wavestack.simulators.mdt693b.personality import MDT693BFaults, MDT693BPersonality
from wavestack.simulators.mdt693b.pty_bridge import PtyBridge

__all__ = ["MDT693BDevice", "MDT693BFaults", "MDT693BPersonality", "PtyBridge"]
